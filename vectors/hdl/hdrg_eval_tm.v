// hdrg_eval_tm.v - time-multiplexed 17-term evaluator (firmware_ref/FORMATS.md step 5), Verilog-2001.
//
// The same arithmetic as hdrg_evaluator.v (bit for bit), computed by ONE shared 32 x 32 -> 64-bit
// signed multiplier and one rounding shifter, driven by a 25-operation program.  Every operation is
//
//     dest <= RHU(A * W, sh) + C          RHU(x, s) = floor(x / 2^s + 1/2) = (x + 2^(s-1)) >>> s
//
// Program (row i of u^i has mantissas c[i][0..3] = m[POLY_INDEX[i][0..3]], FORMATS.md):
//
//   op  A          W        sh             C            dest     what
//   ---- for i = 3, 2, 1, 0 -----------------------------------------------------------
//   L   c[i][3]    1        0              0            acc      p = c3
//   M   acc        v        30             c[i][2]      acc      p = RHU(p v, 30) + c2
//   M   acc        v        30             c[i][1]      acc      p = RHU(p v, 30) + c1
//   M   acc        v        30             c[i][0]      acc      q = RHU(p v, 30) + c0
//   A   acc        1        e_i - E        0            t (i=3)  a_i = RHU(q, e_i - E)
//                                                       acc (i<3)
//   H   t          u        30             acc          t        t = RHU(t u, 30) + a_i  (i < 3)
//   ---- then -------------------------------------------------------------------------
//   Z   m_7        clamp(z) 30 + e_7 - E   t            t        t += RHU(m_7 z, 30 + e_7 - E)
//   B   t          2^(21-E) E - 21         0            b        B (E < 21: W = 2^(21-E), sh = 0;
//                  or 1     or 0                                    E >= 21: W = 1, sh = E - 21)
//
// 25 operations, each 5 clock cycles through the pipeline below (no overlap: each depends on the
// previous one), so a sample takes 1 (start) + 25 * 5 = 126 cycles from `start` to `done`:
//
//   cycle 0  read the table memory at the op's mantissa index (synchronous read)
//   cycle 1  P  <= A * W                 (the shared multiplier: 32 x 32 signed); half <= 2^(sh-1)
//   cycle 2  P2 <= P + half              (rounding constant, 0 when sh = 0)
//   cycle 3  S  <= P2 >>> sh             (the shared barrel shifter, sh in 0..61)
//   cycle 4  dest <= S + C
//
// Widths: the quantizer's interval bound (every row's |mantissa| sum and the aligned row bounds
// plus the k7 bound at most 2^31 - 1; the C twin checks it: HDRG_ERR_HORNER) keeps p, q, a_i and t
// within +-(2^31 - 1), so acc and t are 32-bit registers; |A W| < 2^62; B < 2^53 in 64 bits.
//
// Table load (the coefficient table layout, FORMATS.md): write word k of the table through
// (we, waddr, wdata): words 22..27 are the exponents e_0..e_3, e_7, E (6 bits), words 28..44 the
// mantissas m_0..m_16; a two-bank table (layout v2) adds bank 2's exponents (49..54) and mantissas
// (55..71), selected per sample by `bank` (a 64 x 32 memory; Yosys maps it to block RAM).  Other
// addresses are ignored (the header, CRC and checks are the loader's job).  Do not write while busy.
//
// `define HDRG_BREAK_ROUNDING builds a deliberately wrong evaluator (RHU truncates), HDRG_BREAK_BANK
// one that reads bank 1's mantissas for bank 2.
//
// Sharing (hdrg_top): while idle, the multiplier computes xp <= xa * xw every cycle for a client
// (hdrg_top's front-end ALU), so the pipeline needs one 32 x 32 multiplier for both; and so do the
// rounding adder and the shifter: xs <= RHU(xsum, xsh) two cycles after xsum, xsh (held stable
// from the cycle before xsum: the rounding constant is registered from xsh).  HDRG_BREAK_ROUNDING
// truncates there too.  Z_LATE = 1:
// z is sampled at the Z operation instead of at start, and the evaluator waits there while `zhold`
// is high (the aux generators of hdrg_top run in parallel with the Horner rows).
`timescale 1ns / 1ns
module hdrg_eval_tm #(
    parameter Z_LATE = 0
) (
    input  wire               clk,
    input  wire               rst,        // synchronous, active high: idle, done low
    input  wire               we,         // table word write
    input  wire [6:0]         waddr,      // table word index (22..44; bank 2: 49..71)
    input  wire [31:0]        wdata,
    input  wire               start,      // one-cycle pulse: evaluate u, v, z, bank (sampled at start)
    input  wire               bank,       // 0: bank 1 (words 22..44), 1: bank 2 (words 49..71)
    input  wire signed [31:0] u,          // Q1.30 proxy, in [-2^30, 2^30]
    input  wire signed [31:0] v,          // Q1.30 proxy rate, in [-2^30, 2^30]
    input  wire signed [31:0] z,          // Q1.30 aux word, any int32 (clamped)
    output reg  signed [63:0] b,          // bias B, LSB 2^-21 deg/h (valid with done)
    output reg                z_clamped,
    output reg                busy,
    output reg                done,       // one-cycle pulse when b is valid
    input  wire signed [31:0] xa,         // the shared multiplier while idle: xp <= xa * xw
    input  wire signed [31:0] xw,
    output wire signed [63:0] xp,
    input  wire signed [63:0] xsum,       // the shared rounding shifter while idle: xs <= RHU(xsum, xsh)
    input  wire [5:0]         xsh,
    output wire signed [63:0] xs,
    input  wire               zhold       // Z_LATE: wait at the Z operation while high
);
    localparam signed [31:0] ONE = 32'sd1073741824;   // 2^30
    wire z_hi = !z[31] && z[30] && (|z[29:0]);       // z > 2^30 (bit tests, no comparators)
    wire z_lo = z[31] && !z[30];                      // z < -2^30

    // ---- table: exponents in registers, mantissas in a memory (bank 1 at 0..16, bank 2 at 32..48) ----
    reg [31:0] mant [0:63];
    reg [5:0]  e1_0, e1_1, e1_2, e1_3, e1_7, e1_acc, e2_0, e2_1, e2_2, e2_3, e2_7, e2_acc;
    wire [5:0] mwa1 = waddr[5:0] - 6'd28;    // 28..44 -> 0..16
    wire [5:0] mwa2 = waddr[5:0] - 6'd23;    // 55..71 -> 32..48 (mod 64)
    always @(posedge clk) begin
        if (we && waddr >= 7'd28 && waddr <= 7'd44)
            mant[mwa1] <= wdata;
        if (we && waddr >= 7'd55 && waddr <= 7'd71)
            mant[mwa2] <= wdata;
        if (we) begin
            case (waddr)
                7'd22: e1_0   <= wdata[5:0];
                7'd23: e1_1   <= wdata[5:0];
                7'd24: e1_2   <= wdata[5:0];
                7'd25: e1_3   <= wdata[5:0];
                7'd26: e1_7   <= wdata[5:0];
                7'd27: e1_acc <= wdata[5:0];
                7'd49: e2_0   <= wdata[5:0];
                7'd50: e2_1   <= wdata[5:0];
                7'd51: e2_2   <= wdata[5:0];
                7'd52: e2_3   <= wdata[5:0];
                7'd53: e2_7   <= wdata[5:0];
                7'd54: e2_acc <= wdata[5:0];
                default: ;
            endcase
        end
    end
    reg bank_q;                         // the bank of the sample (latched at start)
    wire [5:0] e_row0 = bank_q ? e2_0 : e1_0, e_row1 = bank_q ? e2_1 : e1_1, e_row2 = bank_q ? e2_2 : e1_2;
    wire [5:0] e_row3 = bank_q ? e2_3 : e1_3, e_7 = bank_q ? e2_7 : e1_7, e_acc = bank_q ? e2_acc : e1_acc;

    // ---- the program counter: row i (3..0) and position pos within it ----
    // pos 0 L, 1..3 M (c2, c1, c0), 4 A, 5 H (rows 2..0), 6 Z, 7 B
    reg [1:0] row;
    reg [2:0] pos;
    reg [4:0] midx;                     // mantissa index read by this op
    always @* begin
        case ({row, pos[1:0]})          // c[row][3 - pos] for L (pos 0) and M (pos 1..3)
            4'b00_00: midx = 5'd6;  4'b00_01: midx = 5'd5;  4'b00_10: midx = 5'd4;  4'b00_11: midx = 5'd0;
            4'b01_00: midx = 5'd10; 4'b01_01: midx = 5'd9;  4'b01_10: midx = 5'd8;  4'b01_11: midx = 5'd1;
            4'b10_00: midx = 5'd13; 4'b10_01: midx = 5'd12; 4'b10_10: midx = 5'd11; 4'b10_11: midx = 5'd2;
            default:  case (pos[1:0])
                          2'd0: midx = 5'd16; 2'd1: midx = 5'd15; 2'd2: midx = 5'd14; default: midx = 5'd3;
                      endcase
        endcase
        if (pos >= 3'd4)
            midx = 5'd7;                // Z reads m_7 (A, H, B read nothing)
    end

    // shift amounts and the B scale, registered from the exponents of the sample's bank (valid from
    // the cycle after start on)
    reg [5:0] sh_row0, sh_row1, sh_row2, sh_row3, sh_z, sh_b;
    reg signed [31:0] bscale;
    always @(posedge clk) begin
        sh_row0 <= e_row0 - e_acc;
        sh_row1 <= e_row1 - e_acc;
        sh_row2 <= e_row2 - e_acc;
        sh_row3 <= e_row3 - e_acc;
        sh_z <= 6'd30 + e_7 - e_acc;
        sh_b <= (e_acc >= 6'd21) ? e_acc - 6'd21 : 6'd0;
        bscale <= (e_acc >= 6'd21) ? 32'sd1 : (32'sd1 <<< (6'd21 - e_acc));
    end

    // ---- registers of the sample ----
    reg signed [31:0] uq, vq, zq;       // inputs latched at start (zq clamped)
    reg signed [31:0] acc, t;
    reg [2:0]  phase;                   // 0..4 within an op
    reg [31:0] mrd;                     // memory read data (cycle 0 -> 1)
    reg signed [31:0] a_op, w_op, c_op;
    reg [5:0]  sh;
    reg [1:0]  dest;                    // 0 acc, 1 t, 2 b
    reg signed [63:0] p, p2, s;
    assign xp = p;
    assign xs = s;
    reg signed [31:0] c_q;              // C held to cycle 4
    reg [1:0]  dest_q;

    // operand select (from the registers and the memory word read in cycle 0)
    always @* begin
        a_op = acc;
        w_op = 32'sd1;
        c_op = 32'sd0;
        sh = 6'd0;
        dest = 2'd0;
        case (pos)
            3'd0: a_op = mrd;                                              // L
            3'd1, 3'd2, 3'd3: begin w_op = vq; sh = 6'd30; c_op = mrd; end   // M
            3'd4: begin                                                    // A
                case (row)
                    2'd0: sh = sh_row0;
                    2'd1: sh = sh_row1;
                    2'd2: sh = sh_row2;
                    default: sh = sh_row3;
                endcase
                dest = (row == 2'd3) ? 2'd1 : 2'd0;
            end
            3'd5: begin a_op = t; w_op = uq; sh = 6'd30; c_op = acc; dest = 2'd1; end   // H
            3'd6: begin a_op = mrd; w_op = zq; sh = sh_z; c_op = t; dest = 2'd1; end     // Z
            default: begin a_op = t; w_op = bscale; sh = sh_b; dest = 2'd2; end       // B
        endcase
    end

    reg [5:0] sh_q, sh_q2;
    reg signed [63:0] half;             // 2^(sh-1), 0 when sh = 0 (registered with P)

    // the one rounding adder and shifter: the program's in phases 1..3, the client's while idle
    // (one decoder, adder and shifter: their operands selected by busy)
    wire [5:0] h_sh = busy ? sh : xsh;
    wire signed [63:0] h_dec = (h_sh == 6'd0) ? 64'sd0 : (64'sd1 <<< (h_sh - 6'd1));
`ifdef HDRG_BREAK_ROUNDING
    wire signed [63:0] p2_sum = busy ? p : xsum;
`else
    wire signed [63:0] p2_sum = (busy ? p : xsum) + half;
`endif
    wire [5:0] sh2_in = busy ? sh_q : xsh;

    // the one multiplier: the program's A W in phase 1, the client's xa xw while idle
    wire signed [31:0] ma = busy ? a_op : xa;
    wire signed [31:0] mw = busy ? w_op : xw;
    always @(posedge clk)
        if (!busy || phase == 3'd1)
            p <= ma * mw;

    always @(posedge clk) begin
        done <= 1'b0;
        if (rst) begin
            busy <= 1'b0;
            row <= 2'd3;
            pos <= 3'd0;
            phase <= 3'd0;
        end else if (!busy) begin
            // the client's rounding shift (hdrg_top's ALU): half from xsh, then p2, then s
            half <= h_dec;
            p2 <= p2_sum;
            sh_q2 <= sh2_in;
            s <= p2 >>> sh_q2;
            if (start) begin
                busy <= 1'b1;
                row <= 2'd3;
                pos <= 3'd0;
                phase <= 3'd0;
                uq <= u;
                bank_q <= bank;
                vq <= v;
                z_clamped <= z_hi || z_lo;
                zq <= z_hi ? ONE : (z_lo ? -ONE : z);
            end
        end else begin
            case (phase)
                3'd0: if (Z_LATE == 0 || pos != 3'd6 || !zhold) begin
                    if (Z_LATE != 0 && pos == 3'd6) begin
                        z_clamped <= z_hi || z_lo;
                        zq <= z_hi ? ONE : (z_lo ? -ONE : z);
                    end
`ifdef HDRG_BREAK_BANK
                    mrd <= mant[{1'b0, midx}];          // wrong on purpose: bank 2's mantissas ignored
`else
                    mrd <= mant[{bank_q, midx}];
`endif
                    phase <= 3'd1;
                end
                3'd1: begin
                    c_q <= c_op;
                    sh_q <= sh;
                    half <= h_dec;
                    dest_q <= dest;
                    phase <= 3'd2;
                end
                3'd2: begin
                    p2 <= p2_sum;
                    sh_q2 <= sh2_in;
                    phase <= 3'd3;
                end
                3'd3: begin
                    s <= p2 >>> sh_q2;
                    phase <= 3'd4;
                end
                default: begin
                    case (dest_q)
                        2'd0: acc <= s[31:0] + c_q;
                        2'd1: t <= s[31:0] + c_q;
                        default: b <= s;                // B: C = 0 (no 64-bit adder)
                    endcase
                    phase <= 3'd0;
                    // next op: row 3 ends after A; rows 2..0 after H; then Z, B
                    if (pos == 3'd7) begin
                        busy <= 1'b0;
                        done <= 1'b1;
                    end else if ((pos == 3'd4 && row == 2'd3) || (pos == 3'd5 && row != 2'd0)) begin
                        row <= row - 2'd1;
                        pos <= 3'd0;
                    end else
                        pos <= pos + 3'd1;
                end
            endcase
        end
    end
endmodule
