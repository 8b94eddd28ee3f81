// hdrg_div.v - div_round_scaled of firmware_ref/arith.py for the combiner (Verilog-2001).
//
//     q = div_round_scaled(a, b, k) = floor((a 2^(k+1) + b) / (2 b))        (b > 0)
//
// which equals floor_div(a, b) 2^k + floor_div(2 (r << k) + b, 2 b) with r = a - floor_div(a, b) b
// (FORMATS.md primitives; both are floor(a 2^k / b + 1/2) of exact integers).  With N = a 2^(k+1) + b
// and D = 2 b: q = N / D for N >= 0, -((-N + D - 1) / D) for N < 0 (unsigned division of the
// magnitudes).  A restoring divider produces QB = 44 quotient bits, one per clock cycle (no DSP);
// `ovf` says |q| >= 2^44 (the caller clamps).  Used with a = window sum (|a| <= cnt 2^31, k = 10:
// |q| < 2^42) and a = mean difference (|a| < 2^43, k = 16, clamped to +-(2^40 - 1) by the caller).
// Cycles: start, setup (overflow check), QB steps, result: QB + 3 = 47.
`timescale 1ns / 1ns
module hdrg_div (
    input  wire               clk,
    input  wire               start,
    input  wire signed [63:0] a,
    input  wire [35:0]        b,          // b > 0, < 2^35
    /* verilator lint_off UNUSEDSIGNAL */
    input  wire [4:0]         k,          // 10 or 16 (only these: a two-way shift, no barrel shifter)
    /* verilator lint_on UNUSEDSIGNAL */
    output reg  signed [63:0] q,
    output reg                ovf,
    output reg                done
);
    localparam QB = 44;
    // |N| < 2^63 2^17 + 2^35 < 2^81; D < 2^37
    reg [81:0] nmag;                 // |N| (+ D - 1 when N < 0)
    reg [37:0] rem;                  // partial remainder, < D
    reg [36:0] d;
    reg [QB-1:0] quo;
    reg neg, busy = 1'b0, setup = 1'b0;
    reg [5:0] i;
    reg signed [81:0] n_s;
    reg [38:0] trial;
    wire signed [44:0] qs = neg ? -$signed({1'b0, quo}) : $signed({1'b0, quo});
    always @* begin
        n_s = (k[4] ? $signed({{1{a[63]}}, a, 17'd0}) : $signed({{7{a[63]}}, a, 11'd0})) + $signed({46'd0, b});
        trial = {rem, nmag[QB-1]} - {2'b00, d};
    end
    always @(posedge clk) begin
        done <= 1'b0;
        if (start) begin
            neg <= n_s[81];
            d <= {b, 1'b0};
            setup <= 1'b1;
            // |N|, plus D - 1 when N < 0 (floor of a negative quotient)
            nmag <= n_s[81] ? (-n_s + $signed({45'd0, b, 1'b0}) - 82'sd1) : n_s;
        end else if (setup) begin
            // the quotient's bits above QB must be zero: |N| >> QB < D, else overflow
            ovf <= nmag[81:QB] >= {1'b0, d};
            rem <= nmag[81:QB];
            setup <= 1'b0;
            busy <= 1'b1;
            i <= 6'd0;
        end else if (busy) begin
            if (i < QB) begin
                if (!trial[38]) begin
                    rem <= trial[37:0];
                    quo <= {quo[QB-2:0], 1'b1};
                end else begin
                    rem <= {rem[36:0], nmag[QB-1]};
                    quo <= {quo[QB-2:0], 1'b0};
                end
                nmag <= {nmag[81:QB], nmag[QB-2:0], 1'b0};
                i <= i + 6'd1;
            end else begin
                q <= {{19{qs[44]}}, qs};                 // |q| < 2^44: a 45-bit negation
                busy <= 1'b0;
                done <= 1'b1;
            end
        end
    end
endmodule
