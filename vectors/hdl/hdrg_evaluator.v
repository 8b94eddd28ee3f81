// hdrg_evaluator.v - the 17-term bias evaluator of firmware_ref/FORMATS.md step 5, Verilog-2001.
//
// Combinational and synthesizable: 15 Horner multiply-adds (32 x 32 -> 64-bit signed products:
// the quantizer's interval analysis keeps every accumulator within +-(2^31 - 1)) and one k7 z
// product, each rounded half up (RHU: add 2^(s-1), arithmetic shift right by s).
//
//   for i in 3..0:  p = c[i][3]; p = RHU(p v, 30) + c[i][2]; p = RHU(p v, 30) + c[i][1];
//                   q = RHU(p v, 30) + c[i][0]; a[i] = RHU(q, e_i - E)
//   t = RHU(RHU(RHU(a3 u, 30) + a2) u, 30) + a1) u, 30) + a0   (Horner in u)
//   t = t + RHU(m_7 clamp(z), 30 + e_7 - E)
//   B = E >= 21 ? RHU(t, E - 21) : t << (21 - E)                (LSB 2^-21 deg/h)
//
// c[i][j] = m[POLY_INDEX[i][j]]: row u^0 = (k0, k4, k5, k6), u^1 = (k1, k8, k9, k10),
// u^2 = (k2, k11, k12, k13), u^3 = (k3, k14, k15, k16) (v^0..v^3).  The mantissas and exponents
// are the coefficient table's words 28..44 and 22..27 (FORMATS.md "Coefficient table layout",
// version 2); bank 2 (a regress_first table, order 1) is words 55..71 and 49..54.
//
// Bank select (regress, then reverse): `bank` = 1 evaluates bank 2 (mant2, e2_*; the firmware
// sets it on mode-2 samples of a two-bank table), 0 bank 1; the datapath is shared (one Horner
// evaluation per sample), only the coefficient/exponent multiplexer is added.
//
// `define HDRG_BREAK_ROUNDING builds a deliberately wrong evaluator (RHU truncates), `define
// HDRG_BREAK_BANK one that ignores bank 2's mantissas; the testbench must catch both.
`timescale 1ns / 1ns
module hdrg_evaluator (
    input  wire               bank,     // 0: bank 1 (mant, e_*), 1: bank 2 (mant2, e2_*)
    input  wire [17*32-1:0]   mant1,    // bank 1: m_k in bits [32k+31 : 32k], two's complement
    input  wire [5:0]         e1_0,     // bank 1: exponent of row u^0 (0..52)
    input  wire [5:0]         e1_1,
    input  wire [5:0]         e1_2,
    input  wire [5:0]         e1_3,
    input  wire [5:0]         e1_7,     // bank 1: exponent of k7
    input  wire [5:0]         e1_acc,   // bank 1: accumulator exponent E; e_g - E in 0..31
    input  wire [17*32-1:0]   mant2,    // bank 2 (words 55..71), same formats
    input  wire [5:0]         e2_0,
    input  wire [5:0]         e2_1,
    input  wire [5:0]         e2_2,
    input  wire [5:0]         e2_3,
    input  wire [5:0]         e2_7,
    input  wire [5:0]         e2_acc,
    input  wire signed [31:0] u,        // Q1.30 proxy, in [-2^30, 2^30]
    input  wire signed [31:0] v,        // Q1.30 proxy rate, in [-2^30, 2^30]
    input  wire signed [31:0] z,        // Q1.30 aux word, any int32 (clamped to [-2^30, 2^30])
    output wire signed [63:0] b,        // bias B, LSB 2^-21 deg/h
    output wire               z_clamped // z was outside [-2^30, 2^30]
);
    localparam signed [31:0] ONE = 32'sd1073741824;   // 2^30

    // the selected bank (`define HDRG_BREAK_BANK: bank 2's mantissas are ignored, on purpose)
`ifdef HDRG_BREAK_BANK
    wire [17*32-1:0] mant  = mant1;
`else
    wire [17*32-1:0] mant  = bank ? mant2  : mant1;
`endif
    wire [5:0]       e_0   = bank ? e2_0   : e1_0;
    wire [5:0]       e_1   = bank ? e2_1   : e1_1;
    wire [5:0]       e_2   = bank ? e2_2   : e1_2;
    wire [5:0]       e_3   = bank ? e2_3   : e1_3;
    wire [5:0]       e_7   = bank ? e2_7   : e1_7;
    wire [5:0]       e_acc = bank ? e2_acc : e1_acc;

    // RHU(x, s) = floor(x / 2^s + 1/2), s in 0..63
    function signed [63:0] rhu;
        input signed [63:0] x;
        input [6:0] s;
        begin
            if (s == 7'd0)
                rhu = x;
            else
`ifdef HDRG_BREAK_ROUNDING
                rhu = x >>> s;                                    // wrong on purpose: truncates
`else
                rhu = (x + (64'sd1 <<< (s - 7'd1))) >>> s;
`endif
        end
    endfunction

    // RHU(a w, 30); |a| <= 2^31 - 1 (proved by the table's bounds), |w| <= 2^30
    function signed [63:0] mul_rhu30;
        input signed [63:0] a;
        input signed [31:0] w;
        reg signed [63:0] w64;
        begin
            w64 = w;                                              // sign extension
            mul_rhu30 = rhu(a * w64, 7'd30);
        end
    endfunction

    // one Horner row in v, aligned to the accumulator by s = e_i - E
    function signed [63:0] row;
        input signed [31:0] c0, c1, c2, c3;
        input signed [31:0] w;
        input [6:0] s;
        reg signed [63:0] p;
        begin
            p = c3;
            p = mul_rhu30(p, w) + c2;
            p = mul_rhu30(p, w) + c1;
            p = mul_rhu30(p, w) + c0;
            row = rhu(p, s);
        end
    endfunction

    wire signed [31:0] m0  = mant[ 0*32 +: 32], m1  = mant[ 1*32 +: 32], m2  = mant[ 2*32 +: 32];
    wire signed [31:0] m3  = mant[ 3*32 +: 32], m4  = mant[ 4*32 +: 32], m5  = mant[ 5*32 +: 32];
    wire signed [31:0] m6  = mant[ 6*32 +: 32], m7  = mant[ 7*32 +: 32], m8  = mant[ 8*32 +: 32];
    wire signed [31:0] m9  = mant[ 9*32 +: 32], m10 = mant[10*32 +: 32], m11 = mant[11*32 +: 32];
    wire signed [31:0] m12 = mant[12*32 +: 32], m13 = mant[13*32 +: 32], m14 = mant[14*32 +: 32];
    wire signed [31:0] m15 = mant[15*32 +: 32], m16 = mant[16*32 +: 32];

    wire [6:0] ea = {1'b0, e_acc};
    wire signed [63:0] a0 = row(m0, m4,  m5,  m6,  v, {1'b0, e_0} - ea);
    wire signed [63:0] a1 = row(m1, m8,  m9,  m10, v, {1'b0, e_1} - ea);
    wire signed [63:0] a2 = row(m2, m11, m12, m13, v, {1'b0, e_2} - ea);
    wire signed [63:0] a3 = row(m3, m14, m15, m16, v, {1'b0, e_3} - ea);

    wire signed [63:0] t2 = mul_rhu30(a3, u) + a2;
    wire signed [63:0] t1 = mul_rhu30(t2, u) + a1;
    wire signed [63:0] t0 = mul_rhu30(t1, u) + a0;

    assign z_clamped = (z > ONE) || (z < -ONE);
    wire signed [31:0] zc  = (z > ONE) ? ONE : ((z < -ONE) ? -ONE : z);
    wire signed [63:0] m7w = m7;                                  // sign extension
    wire signed [63:0] zcw = zc;
    wire signed [63:0] t   = t0 + rhu(m7w * zcw, 7'd30 + {1'b0, e_7} - ea);

    assign b = (e_acc >= 6'd21) ? rhu(t, ea - 7'd21) : (t <<< (7'd21 - ea));
endmodule
