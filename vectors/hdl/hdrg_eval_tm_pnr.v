// hdrg_eval_tm_pnr.v - a pin-light wrapper of hdrg_eval_tm for place-and-route (Fmax, fit): an
// UP5K package has too few pins for the evaluator's 200 ports, so the inputs arrive through a
// 128-bit serial shift register (sdi, shift) and B leaves through a 64-bit one (sdo).  Not part of
// a real design; every bit stays observable so that synthesis keeps the whole evaluator.
`timescale 1ns / 1ns
module hdrg_eval_tm_pnr (
    input  wire clk,
    input  wire rst,
    input  wire sdi,
    input  wire shift,      // shift sdi into the input register
    input  wire we,         // write table word sr[31:0] at address sr[38:32]
    input  wire start,      // evaluate u = sr[127:96], v = sr[95:64], z = sr[63:32], bank = sr[39]
    output wire sdo,
    output wire busy,
    output reg  done_q,
    output reg  zc_q
);
    reg [127:0] sr;
    reg [63:0]  so;
    wire signed [63:0] b;
    wire zc, done;
    /* verilator lint_off UNUSEDSIGNAL */
    wire signed [63:0] xp_unused;       // the shared multiplier port: no client here
    wire signed [63:0] xs_unused;       // the shared rounding shifter: no client here
    /* verilator lint_on UNUSEDSIGNAL */
    always @(posedge clk) begin
        if (shift) sr <= {sr[126:0], sdi};
        if (done) so <= b; else so <= {so[62:0], 1'b0};
        done_q <= done;
        zc_q <= zc;
    end
    assign sdo = so[63];
    hdrg_eval_tm ev (.clk(clk), .rst(rst), .we(we), .waddr(sr[38:32]), .wdata(sr[31:0]), .start(start), .bank(sr[39]),
                     .u(sr[127:96]), .v(sr[95:64]), .z(sr[63:32]), .b(b), .z_clamped(zc), .busy(busy), .done(done),
                     .xa(32'sd0), .xw(32'sd0), .xp(xp_unused), .xsum(64'sd0), .xsh(6'd0), .xs(xs_unused), .zhold(1'b0));
endmodule
