// tb_front.v - checks hdrg_front (proxy + rate) against a pipeline vector set (sequencer, e2e, aux):
// the O fields u, v, s and the flag bits 1 (u clamped), 2 (v clamped), 4 (warm-up) of every sample.
//
// The record layout differs per set: the bit positions (LSB) of the fields are parameters, which
// host_tools/cost.py computes from manifest.json "mem_record" (-P / -G).  +offsets= names a file of
// table start words (one hex word per table: manifest "table_offsets").  A table is loaded (words
// 3..14) and the rate state cleared whenever the case changes.  Prints
// "RESULT vectors=N mismatches=M cycles=C" (C: the most cycles one sample took).
`timescale 1ns / 1ns
module tb_front;
    parameter MAX_VEC = 65536;
    parameter MAX_TAB = 256;
    parameter MAX_WORDS = 65536;
    parameter REC = 400;
    parameter P_CASE = 384, P_F = 352, P_T = 320, P_RESTART = 240, P_U = 168, P_V = 136, P_S = 72, P_FLAGS = 0;
    parameter SHOW = 10;

    reg [REC-1:0] vec [0:MAX_VEC-1];
    reg [31:0] tab [0:MAX_WORDS-1];
    reg [31:0] offs [0:MAX_TAB-1];
    reg [8*1024-1:0] vec_path, tab_path, off_path;
    integer n_vec, n_words, n_tab, i, k, base, bad, t, loaded, cyc, most;
    reg [REC-1:0] r;
    reg [7:0] fl;

    reg clk = 1'b0, we = 1'b0, clear = 1'b0, start = 1'b0, restart = 1'b0;
    reg [5:0] waddr = 6'd0;
    reg [31:0] wdata = 32'd0, pw = 32'd0;
    wire signed [31:0] u, v;
    wire signed [63:0] s;
    wire uc, vc, warm, busy, done;

    hdrg_front dut (.clk(clk), .we(we), .waddr(waddr), .wdata(wdata), .clear(clear), .start(start), .pw(pw),
                    .restart(restart), .u(u), .uc(uc), .v(v), .vc(vc), .s(s), .warm(warm), .busy(busy), .done(done));

    always #5 clk = ~clk;

    initial begin
        if (!$value$plusargs("vectors=%s", vec_path) || !$value$plusargs("tables=%s", tab_path)
            || !$value$plusargs("offsets=%s", off_path) || !$value$plusargs("n_vec=%d", n_vec)
            || !$value$plusargs("n_words=%d", n_words) || !$value$plusargs("n_tab=%d", n_tab)) begin
            $display("ERROR: give +vectors= +tables= +offsets= +n_vec= +n_words= +n_tab=");
            $finish;
        end
        $readmemh(vec_path, vec, 0, n_vec - 1);
        $readmemh(tab_path, tab, 0, n_words - 1);
        $readmemh(off_path, offs, 0, n_tab - 1);
        bad = 0;
        loaded = -1;
        most = 0;
        @(negedge clk);
        for (i = 0; i < n_vec; i = i + 1) begin
            r = vec[i];
            t = r[P_CASE +: 16];
            if (t != loaded) begin
                base = offs[t];
                if (tab[base] !== 32'h47524448) begin
                    $display("ERROR: vector %0d: table %0d at word %0d has no magic", i, t, base);
                    $finish;
                end
                for (k = 3; k <= 14; k = k + 1) begin
                    we = 1'b1;
                    waddr = k;
                    wdata = tab[base + k];
                    @(negedge clk);
                end
                we = 1'b0;
                clear = 1'b1;
                @(negedge clk);
                clear = 1'b0;
                while (busy) @(negedge clk);
                loaded = t;
            end
            pw = tab[base + 3][0] ? r[P_T +: 32] : r[P_F +: 32];
            restart = r[P_RESTART];
            start = 1'b1;
            @(negedge clk);
            start = 1'b0;
            cyc = 1;
            while (!done) begin
                @(negedge clk);
                cyc = cyc + 1;
            end
            if (cyc > most) most = cyc;
            fl = r[P_FLAGS +: 8];
            if (u !== r[P_U +: 32] || v !== r[P_V +: 32] || s !== r[P_S +: 64] || uc !== fl[0] || vc !== fl[1]
                || warm !== fl[2]) begin
                if (bad < SHOW)
                    $display("MISMATCH vector %0d (case %0d): expected u=%0d v=%0d s=%0d flags=%0d, got u=%0d v=%0d s=%0d uc=%0d vc=%0d warm=%0d",
                             i, t, $signed(r[P_U +: 32]), $signed(r[P_V +: 32]), $signed(r[P_S +: 64]), fl, u, v, s,
                             uc, vc, warm);
                bad = bad + 1;
            end
        end
        $display("RESULT vectors=%0d mismatches=%0d cycles=%0d", n_vec, bad, most);
        $finish;
    end
endmodule
