// hdrg_aux_pnr.v - a pin-light wrapper of hdrg_aux for place-and-route (Fmax, fit): an UP5K package
// has too few pins for the aux generators' ~480 ports, so the inputs arrive through a 400-bit serial
// shift register (sdi, shift) and z leaves through a 32-bit one (sdo).  Not part of a real design
// (the shift registers add ~430 FFs); every bit stays observable so that synthesis keeps the whole
// module.  sr (MSB first): inv (bit 388), f 32, t 32, a0..a3 4 x 32, k 64, s 64, z_in 32, mode 2,
// restart, warm (bits 387..32); the table port reads bits 39..0 (waddr, wdata), shared with the last inputs.
`timescale 1ns / 1ns
module hdrg_aux_pnr #(
    parameter OP_CYCLES = 2
) (
    input  wire clk,
    input  wire rst,
    input  wire sdi,
    input  wire shift,      // shift sdi into the input register
    input  wire we,         // write table word sr[31:0] at address sr[39:32]
    input  wire start,      // one sample with the inputs in sr
    output wire sdo,
    output wire busy,
    output reg  done_q,
    output reg  zc_q
);
    reg [399:0] sr;
    reg [31:0]  so;
    wire signed [31:0] z;
    wire zc, done;
    always @(posedge clk) begin
        if (shift) sr <= {sr[398:0], sdi};
        if (done) so <= z; else so <= {so[30:0], 1'b0};
        done_q <= done;
        zc_q <= zc;
    end
    assign sdo = so[31];
    hdrg_aux #(.OP_CYCLES(OP_CYCLES)) aux (.clk(clk), .rst(rst), .we(we), .waddr(sr[39:32]), .wdata(sr[31:0]), .start(start),
                  .f_word(sr[387:356]), .t_word(sr[355:324]), .a0(sr[323:292]), .a1(sr[291:260]), .a2(sr[259:228]),
                  .a3(sr[227:196]), .k(sr[195:132]), .s(sr[131:68]), .z_in(sr[67:36]), .mode(sr[35:34]),
                  .restart(sr[33]), .inv(sr[388]), .warm(sr[32]), .z(z), .z_clamped(zc), .busy(busy), .done(done));
endmodule
