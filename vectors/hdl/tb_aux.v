// tb_aux.v - checks hdrg_aux (the aux generators) against the aux vector set: the O field z and flag
// bit 32 (z clamped) of every sample.
//
// The record layout is given by parameters (LSB positions; host_tools/bench/cost_aux.py computes them from
// manifest.json "mem_record").  The inputs driven per sample are the record's F, T, A0..A3, K,
// RESTART and Z, and from the pipeline's own outputs in the record: the sample's mode (O field
// `mode`: the logged or the timer's mode), the rate sum S (O field `s`) and the warm-up flag (flag
// bit 4).  +offsets= names a file of each CASE's table start word (one hex word per case).  When the
// case changes: reset (power-on), then write every word of the case's table (0 .. length - 2, in
// address order) through the write port.  Prints "RESULT vectors=N mismatches=M cycles=C" (C: the
// most cycles from start to done of one sample) and "CYCLES min=.. max=..", and the first mismatches.
//   iverilog -g2001 -Wall -P tb_aux.REC=.. -o tb_aux tb_aux.v hdrg_aux.v && vvp tb_aux +vectors=.. ...
//   or (Verilator 5): --binary -G... --top-module tb_aux tb_aux.v hdrg_aux.v
`timescale 1ns / 1ns
module tb_aux;
    parameter MAX_VEC = 65536;
    parameter MAX_TAB = 256;
    parameter MAX_WORDS = 65536;
    parameter REC = 848;
    parameter P_CASE = 832, P_F = 800, P_T = 768, P_RESTART = 688, P_Z = 648, P_K = 584, P_A0 = 552, P_A1 = 520,
              P_A2 = 488, P_A3 = 456, P_MODE = 440, P_ZOUT = 360, P_S = 296, P_FLAGS = 0;
    parameter SHOW = 10;
    parameter OP_CYCLES = 2;             // hdrg_aux's cycles per operation (2 or 4)

    reg [REC-1:0] vec [0:MAX_VEC-1];
    reg [31:0] tab [0:MAX_WORDS-1];
    reg [31:0] offs [0:MAX_TAB-1];
    reg [8*1024-1:0] vec_path, tab_path, off_path;
    integer n_vec, n_words, n_tab, i, k, base, bad, t, loaded, cyc, most, least, len;
    reg [REC-1:0] r;
    reg [7:0] fl;

    reg clk = 1'b0, rst = 1'b1, we = 1'b0, start = 1'b0, restart = 1'b0, warm = 1'b0;
    reg [7:0] waddr = 8'd0;
    reg [31:0] wdata = 32'd0, f_word = 32'd0;
    reg signed [31:0] t_word = 0, a0 = 0, a1 = 0, a2 = 0, a3 = 0, z_in = 0;
    reg signed [63:0] k_in = 0, s = 0;
    reg [1:0] mode = 2'd0;
    wire signed [31:0] z;
    wire zc, busy, done;

    hdrg_aux #(.OP_CYCLES(OP_CYCLES)) dut (.clk(clk), .rst(rst), .we(we), .waddr(waddr), .wdata(wdata), .start(start), .f_word(f_word),
                  .t_word(t_word), .a0(a0), .a1(a1), .a2(a2), .a3(a3), .k(k_in), .mode(mode), .restart(restart), .inv(1'b0),
                  .s(s), .warm(warm), .z_in(z_in), .z(z), .z_clamped(zc), .busy(busy), .done(done));

    always #5 clk = ~clk;

    initial begin
        if (!$value$plusargs("vectors=%s", vec_path) || !$value$plusargs("tables=%s", tab_path)
            || !$value$plusargs("offsets=%s", off_path) || !$value$plusargs("n_vec=%d", n_vec)
            || !$value$plusargs("n_words=%d", n_words) || !$value$plusargs("n_tab=%d", n_tab)) begin
            $display("ERROR: give +vectors= +tables= +offsets= +n_vec= +n_words= +n_tab=");
            $finish;
        end
        if (n_vec > MAX_VEC || n_tab > MAX_TAB || n_words > MAX_WORDS) begin
            $display("ERROR: more than %0d vectors, %0d cases or %0d table words", MAX_VEC, MAX_TAB, MAX_WORDS);
            $finish;
        end
        $readmemh(vec_path, vec, 0, n_vec - 1);
        $readmemh(tab_path, tab, 0, n_words - 1);
        $readmemh(off_path, offs, 0, n_tab - 1);
        bad = 0;
        loaded = -1;
        most = 0;
        least = 1 << 30;
        @(negedge clk);
        for (i = 0; i < n_vec; i = i + 1) begin
            r = vec[i];
            t = r[P_CASE +: 16];
            if (t != loaded) begin
                base = offs[t];
                len = tab[base + 2];
                if (tab[base] !== 32'h47524448 || len < 73 || len > 255) begin    // 255: 16 terms, 4 channels
                    $display("ERROR: vector %0d: case %0d's table at word %0d: no magic or length %0d not 73..255",
                             i, t, base, len);
                    $finish;
                end
                rst = 1'b1;
                @(negedge clk);
                rst = 1'b0;
                for (k = 0; k < len - 1; k = k + 1) begin
                    we = 1'b1;
                    waddr = k;
                    wdata = tab[base + k];
                    @(negedge clk);
                end
                we = 1'b0;
                loaded = t;
            end
            f_word = r[P_F +: 32];
            t_word = r[P_T +: 32];
            a0 = r[P_A0 +: 32];
            a1 = r[P_A1 +: 32];
            a2 = r[P_A2 +: 32];
            a3 = r[P_A3 +: 32];
            k_in = r[P_K +: 64];
            z_in = r[P_Z +: 32];
            restart = r[P_RESTART];
            mode = r[P_MODE +: 2];
            s = r[P_S +: 64];
            fl = r[P_FLAGS +: 8];
            warm = fl[2];
            start = 1'b1;
            @(negedge clk);
            start = 1'b0;
            f_word = 32'hxxxxxxxx;    // the module registers its inputs at start
            t_word = 32'hxxxxxxxx;
            k_in = 64'hxxxxxxxxxxxxxxxx;
            s = 64'hxxxxxxxxxxxxxxxx;
            cyc = 1;
            while (!done) begin
                @(negedge clk);
                cyc = cyc + 1;
                if (cyc > 2000) begin                     // the worst table: 838 (16 osc terms, OP_CYCLES 4)
                    $display("ERROR: vector %0d: no done after 2000 cycles", i);
                    $finish;
                end
            end
            if (cyc > most) most = cyc;
            if (cyc < least) least = cyc;
            if (z !== r[P_ZOUT +: 32] || zc !== fl[5]) begin
                if (bad < SHOW)
                    $display("MISMATCH vector %0d (case %0d): expected z=%0d clamped=%0d, got z=%0d clamped=%0d",
                             i, t, $signed(r[P_ZOUT +: 32]), fl[5], z, zc);
                bad = bad + 1;
            end
        end
        $display("CYCLES min=%0d max=%0d", least, most);
        $display("RESULT vectors=%0d mismatches=%0d cycles=%0d", n_vec, bad, most);
        $finish;
    end
endmodule
