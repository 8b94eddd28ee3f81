// tb_eval_tm.v - checks hdrg_eval_tm (the time-multiplexed evaluator) against the evaluator set.
//
// Same files and plusargs as tb_evaluator.v (+vectors=, +tables=, +n_vec=, +n_tab=), and optionally
// +offsets= (a file with each table's first word; default table k at word TAB_WORDS k).  The record
// layout is given by parameters (LSB positions; host_tools/bench/cost.py computes them from manifest.json
// "mem_record"; HAS_BANK: the record has the bank column of layout v2, 1 or 2).  For each vector
// whose table differs from the loaded one, writes the table's words 22..44 (and 49..71 when the
// table is 72 words or longer: bank 2) through the write port, then pulses start and waits for
// done; compares B and zclamped; counts the clock cycles from start to done.  Prints "RESULT vectors=N mismatches=M cycles=C" (C: cycles of
// one sample, the same for every sample) and the first mismatches.
//   iverilog -g2001 -Wall -o tb_eval_tm tb_eval_tm.v hdrg_eval_tm.v && vvp tb_eval_tm +n_vec=.. +n_tab=..
//   or (Verilator 5): --binary -Wno-fatal --top-module tb_eval_tm tb_eval_tm.v hdrg_eval_tm.v
`timescale 1ns / 1ns
module tb_eval_tm;
    parameter MAX_VEC = 65536;
    parameter MAX_TAB = 256;
    parameter TAB_WORDS = 48;
    parameter SHOW = 10;
    parameter REC = 184;
    parameter P_CASE = 168, P_U = 136, P_V = 104, P_Z = 72, P_B = 8, P_ZC = 0;
    parameter HAS_BANK = 0, P_BANK = 0;

    reg [REC-1:0] vec [0:MAX_VEC-1];
    reg [31:0]    tab [0:MAX_TAB*TAB_WORDS-1];
    reg [8*1024-1:0] vec_path, tab_path, off_path;
    reg [31:0] offs [0:MAX_TAB-1];
    integer have_offs, n_words;
    integer n_vec, n_tab, i, k, base, bad, t, loaded, cyc, cycles;
    reg [REC-1:0] r;

    reg clk = 1'b0, rst = 1'b1, we = 1'b0, start = 1'b0;
    reg [6:0] waddr = 7'd0;
    reg bank = 1'b0;
    reg [31:0] wdata = 32'd0;
    reg signed [31:0] u = 0, v = 0, z = 0;
    wire signed [63:0] b;
    wire zc, busy, done;

    hdrg_eval_tm dut (.clk(clk), .rst(rst), .we(we), .waddr(waddr), .wdata(wdata), .start(start), .bank(bank), .u(u), .v(v),
                      .z(z), .b(b), .z_clamped(zc), .busy(busy), .done(done),
                     .xa(32'sd0), .xw(32'sd0), .xp(), .xsum(64'sd0), .xsh(6'd0), .xs(), .zhold(1'b0));

    always #5 clk = ~clk;

    initial begin
        if (!$value$plusargs("vectors=%s", vec_path)) vec_path = "../evaluator.mem";
        if (!$value$plusargs("tables=%s", tab_path)) tab_path = "../evaluator.tables.mem";
        if (!$value$plusargs("n_vec=%d", n_vec)) n_vec = -1;
        if (!$value$plusargs("n_tab=%d", n_tab)) n_tab = -1;
        if (n_vec > MAX_VEC || n_tab > MAX_TAB || n_vec < 1 || n_tab < 1) begin
            $display("ERROR: give +n_vec=1..%0d and +n_tab=1..%0d", MAX_VEC, MAX_TAB);
            $finish;
        end
        have_offs = $value$plusargs("offsets=%s", off_path);
        if (!$value$plusargs("n_words=%d", n_words)) n_words = n_tab * TAB_WORDS;
        $readmemh(vec_path, vec, 0, n_vec - 1);
        $readmemh(tab_path, tab, 0, n_words - 1);
        if (have_offs) $readmemh(off_path, offs, 0, n_tab - 1);
        bad = 0;
        loaded = -1;
        cycles = -1;
        @(negedge clk);
        rst = 1'b0;
        for (i = 0; i < n_vec; i = i + 1) begin
            r = vec[i];
            t = r[P_CASE +: 16];
            base = have_offs ? offs[t] : t * TAB_WORDS;
            if (tab[base] !== 32'h47524448 || (!have_offs && tab[base + 2] !== TAB_WORDS)) begin
                $display("ERROR: vector %0d: table %0d at word %0d: no magic or not %0d words", i, t, base, TAB_WORDS);
                $finish;
            end
            if (t != loaded) begin
                for (k = 22; k <= 71; k = k + 1) begin
                    if (k <= 44 || (k >= 49 && tab[base + 2] >= 72)) begin
                        we = 1'b1;
                        waddr = k;
                        wdata = tab[base + k];
                        @(negedge clk);
                    end
                end
                we = 1'b0;
                loaded = t;
            end
            u = r[P_U +: 32];
            v = r[P_V +: 32];
            z = r[P_Z +: 32];
            bank = HAS_BANK ? (r[P_BANK +: 8] == 8'd2) : 1'b0;
            start = 1'b1;
            @(negedge clk);
            start = 1'b0;
            cyc = 1;
            while (!done) begin
                @(negedge clk);
                cyc = cyc + 1;
            end
            if (cycles < 0) cycles = cyc;
            if (cyc != cycles) begin
                $display("ERROR: vector %0d took %0d cycles, the first took %0d", i, cyc, cycles);
                $finish;
            end
            if (b !== r[P_B +: 64] || {7'd0, zc} !== r[P_ZC +: 8]) begin
                if (bad < SHOW)
                    $display("MISMATCH vector %0d (table %0d): u=%0d v=%0d z=%0d: expected B=%0d zclamped=%0d, got B=%0d zclamped=%0d",
                             i, t, u, v, z, $signed(r[P_B +: 64]), r[P_ZC +: 8], b, zc);
                bad = bad + 1;
            end
        end
        $display("RESULT vectors=%0d mismatches=%0d cycles=%0d", n_vec, bad, cycles);
        $finish;
    end
endmodule
