// tb_evaluator.v - checks hdrg_evaluator against the evaluator set of the test vectors.
//
// Reads with $readmemh:
//   evaluator.tables.mem  the coefficient tables, TAB_WORDS 32-bit words each (layout version 2)
//   evaluator.mem         one 192-bit record per vector, MSB first (manifest.json "mem_record"):
//                         case[191:176] u[175:144] v[143:112] z[111:80] bank[79:72] b[71:8]
//                         zclamped[7:0]   (bank 1 or 2: bank 2 selects words 49..71)
// and prints "RESULT vectors=N mismatches=M" (plus the first mismatches).
//
// Run from vectors/hdl (paths and counts can be given as plusargs):
//   iverilog -g2001 -Wall -o tb_evaluator tb_evaluator.v hdrg_evaluator.v
//   vvp tb_evaluator [+vectors=../evaluator.mem] [+tables=../evaluator.tables.mem] [+n_vec=N] [+n_tab=T]
// Without +n_vec/+n_tab the records are counted (Icarus then warns that the files are shorter than
// the memories).  Add -DHDRG_BREAK_ROUNDING to build the deliberately wrong evaluator.
`timescale 1ns / 1ns
module tb_evaluator;
    parameter MAX_VEC = 65536;          // capacity of the vector memory
    parameter MAX_TAB = 256;            // capacity of the table memory (tables)
    parameter TAB_WORDS = 73;           // words per table (72 fields + CRC, no aux parameters)
    parameter SHOW = 10;                // mismatches printed
    localparam REC = 192;

    reg [REC-1:0] vec [0:MAX_VEC-1];
    reg [31:0]    tab [0:MAX_TAB*TAB_WORDS-1];
    reg [8*1024-1:0] vec_path, tab_path;
    integer n_vec, n_tab, i, k, base, bad, t;
    reg [REC-1:0] r;

    reg [17*32-1:0]   mant, mant2;
    reg [5:0]         e0, e1, e2, e3, e7, ea, f0, f1, f2, f3, f7, fa;
    reg               bank;
    reg signed [31:0] u, v, z;
    wire signed [63:0] b;
    wire               zc;

    hdrg_evaluator dut (.bank(bank), .mant1(mant), .e1_0(e0), .e1_1(e1), .e1_2(e2), .e1_3(e3), .e1_7(e7),
                        .e1_acc(ea), .mant2(mant2), .e2_0(f0), .e2_1(f1), .e2_2(f2), .e2_3(f3), .e2_7(f7),
                        .e2_acc(fa), .u(u), .v(v), .z(z), .b(b), .z_clamped(zc));

    initial begin
        if (!$value$plusargs("vectors=%s", vec_path)) vec_path = "../evaluator.mem";
        if (!$value$plusargs("tables=%s", tab_path)) tab_path = "../evaluator.tables.mem";
        if (!$value$plusargs("n_vec=%d", n_vec)) n_vec = -1;
        if (!$value$plusargs("n_tab=%d", n_tab)) n_tab = -1;
        if (n_vec > MAX_VEC || n_tab > MAX_TAB) begin
            $display("ERROR: %0d vectors / %0d tables exceed MAX_VEC %0d / MAX_TAB %0d (override with -P)",
                     n_vec, n_tab, MAX_VEC, MAX_TAB);
            $finish;
        end
        if (n_vec > 0) $readmemh(vec_path, vec, 0, n_vec - 1); else $readmemh(vec_path, vec);
        if (n_tab > 0) $readmemh(tab_path, tab, 0, n_tab * TAB_WORDS - 1); else $readmemh(tab_path, tab);
        if (n_vec < 0) begin
            n_vec = 0;
            while (n_vec < MAX_VEC && ^vec[n_vec] !== 1'bx) n_vec = n_vec + 1;
        end
        bad = 0;
        for (i = 0; i < n_vec; i = i + 1) begin
            r = vec[i];
            t = r[191:176];
            base = t * TAB_WORDS;
            if (tab[base] !== 32'h47524448 || tab[base + 2] !== TAB_WORDS) begin
                $display("ERROR: vector %0d: table %0d is not a %0d-word table (magic %h, length %0d)",
                         i, t, TAB_WORDS, tab[base], tab[base + 2]);
                $finish;
            end
            e0 = tab[base + 22];
            e1 = tab[base + 23];
            e2 = tab[base + 24];
            e3 = tab[base + 25];
            e7 = tab[base + 26];
            ea = tab[base + 27];
            for (k = 0; k < 17; k = k + 1)
                mant[32*k +: 32] = tab[base + 28 + k];
            f0 = tab[base + 49];
            f1 = tab[base + 50];
            f2 = tab[base + 51];
            f3 = tab[base + 52];
            f7 = tab[base + 53];
            fa = tab[base + 54];
            for (k = 0; k < 17; k = k + 1)
                mant2[32*k +: 32] = tab[base + 55 + k];
            bank = (r[79:72] == 8'd2);
            u = r[175:144];
            v = r[143:112];
            z = r[111:80];
            #1;
            if (b !== r[71:8] || {7'd0, zc} !== r[7:0]) begin
                if (bad < SHOW)
                    $display("MISMATCH vector %0d (table %0d, bank %0d): u=%0d v=%0d z=%0d: expected B=%0d zclamped=%0d, got B=%0d zclamped=%0d",
                             i, t, r[79:72], u, v, z, $signed(r[71:8]), r[7:0], b, zc);
                bad = bad + 1;
            end
        end
        $display("RESULT vectors=%0d mismatches=%0d", n_vec, bad);
        $finish;
    end
endmodule
