// hdrg_alu.v - the front end's shared multiply-round unit of hdrg_top (Verilog-2001).
//
//     r <= RHU(a * w + c, sh)        RHU(x, s) = s == 0 ? x : (x + 2^(s-1)) >>> s
//
// a: signed, |a| < 2^59; w: signed 32-bit (every use has w >= 0); c: signed 64-bit; sh 0..63.
// ONE 32 x 32 signed multiplier (outside: hdrg_eval_tm's, shared while the evaluator is idle:
// ma, mw -> mp one cycle later), used twice per operation: a = a_hi 2^28 + a_lo with
// a_hi = a >>> 28 (signed, fits 32 bits) and a_lo = a[27:0] (unsigned), so
// a w = (a_hi w) 2^28 + a_lo w exactly; every product of the pipeline's front end is below 2^63
// (FORMATS.md: dP G_U < 2^62, S G_V < 2^62, n x_out < 2^46, (n - 1) A < 2^58, slope d < 2^63).
// Schedule (6 cycles from start to done): 0 latch, 1 a_hi w, 2 a_lo w, 3 sum + c, 4 + half,
// 5 shift (done).  The rounding (+ half, shift) is the evaluator's, shared like the multiplier:
// xsum (the sum, held from cycle 4 on) and xsh out, xs = RHU(xsum, xsh) back two cycles later; r is
// xs, valid in the `done` cycle only (`define HDRG_BREAK_ROUNDING truncates there).
`timescale 1ns / 1ns
module hdrg_alu (
    input  wire               clk,
    input  wire               start,
    /* verilator lint_off UNUSEDSIGNAL */
    input  wire signed [63:0] a,        // |a| < 2^59: bits 63..60 are sign copies
    /* verilator lint_on UNUSEDSIGNAL */
    input  wire signed [31:0] w,
    input  wire signed [63:0] c,
    input  wire [5:0]         sh,
    output wire signed [63:0] r,        // valid with done
    output reg                done,
    output reg  signed [31:0] ma,       // the shared multiplier's operands ...
    output reg  signed [31:0] mw,
    input  wire signed [63:0] mp,       // ... and its registered product (ma mw of the previous cycle)
    output wire signed [63:0] xsum,     // the shared rounding shifter's operand ...
    output wire [5:0]         xsh,
    input  wire signed [63:0] xs        // ... and RHU(xsum, xsh) two cycles later
);
    reg signed [31:0] a_hi_q, a_lo_q, w_q;
    reg signed [63:0] c_q, p_hi, p;
    reg [5:0] sh_q;
    reg [2:0] ph;
    reg busy = 1'b0;
    assign xsum = p;
    assign xsh = sh_q;
    assign r = xs;
    always @* begin
        ma = (ph == 3'd1) ? a_hi_q : a_lo_q;
        mw = w_q;
    end
    always @(posedge clk) begin
        done <= 1'b0;
        if (start) begin
            a_hi_q <= a[59:28];
            a_lo_q <= {4'd0, a[27:0]};
            w_q <= w;
            c_q <= c;
            sh_q <= sh;
            ph <= 3'd1;
            busy <= 1'b1;
        end else if (busy) begin
            case (ph)
                3'd1: ph <= 3'd2;                       // mp <= a_hi w
                3'd2: begin p_hi <= mp; ph <= 3'd3; end  // mp <= a_lo w
                3'd3: begin p <= (p_hi <<< 28) + mp + c_q; ph <= 3'd4; end
                3'd4: ph <= 3'd5;                       // p2 <= p + half (the evaluator's)
                default: begin                          // s <= p2 >>> sh: r in the next cycle
                    done <= 1'b1;
                    busy <= 1'b0;
                end
            endcase
        end
    end
endmodule
