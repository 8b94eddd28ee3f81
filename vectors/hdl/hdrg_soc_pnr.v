// hdrg_soc_pnr.v - a pin-light wrapper of hdrg_soc for place-and-route (Fmax, fit on an UP5K): the
// host port's address and data arrive through a 41-bit serial shift register (sdi, shift; addr
// sr[40:32], wdata sr[31:0]) and the read word is XOR-folded into 16 registered pins.  Not part of a
// real design (a real host drives the port directly or through its own SPI / bus bridge).
`timescale 1ns / 1ns
module hdrg_soc_pnr (
    input  wire        clk,
    input  wire        rst,
    input  wire        sdi,
    input  wire        shift,
    input  wire        we,
    input  wire        re,
    input  wire        load,
    input  wire        start,
    input  wire        eval_start,
    output wire        busy,
    output reg         done_q,
    output wire        trap,
    output reg  [15:0] fold_q
);
    reg [40:0] sr;
    wire [31:0] rdata;
    wire done;
    always @(posedge clk)
        if (shift) sr <= {sr[39:0], sdi};
    hdrg_soc soc (.clk(clk), .rst(rst), .we(we), .re(re), .addr(sr[40:32]), .wdata(sr[31:0]), .rdata(rdata),
                  .load(load), .start(start), .eval_start(eval_start), .busy(busy), .done(done), .trap(trap));
    always @(posedge clk) begin
        done_q <= done;
        fold_q <= rdata[15:0] ^ rdata[31:16];
    end
endmodule
