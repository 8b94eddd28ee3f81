// hdrg_aux.v - the aux generators (firmware_ref/aux.py, FORMATS.md "Aux generators"), Verilog-2001.
//
// PORT CONTRACT (stable; the full-pipeline top hdrg_top.v instantiates this module):
//
//   clk, rst       clock; synchronous reset, active high (idle, done low, power-on state: the first
//                  sample after rst is treated as a restart, as firmware_ref.compensate's `fresh`)
//   we, waddr,     table word write, the same convention as hdrg_eval_tm.v: word index = the table
//   wdata          layout address (firmware_ref/table.py, FORMATS.md): word 45 aux_gen, words
//                  72..143 the aux parameters (72 n_terms, 73 n_chan, 74.. AF_c (ignored: units
//                  only), then 11 words per term: kind, sign, src, power, weight, c0..c5).  Other
//                  addresses are ignored.  Write the whole table (aux_gen and every aux word) while
//                  idle; any write puts the generators back to power-on (next sample = restart).
//                  waddr is 8 bits (the aux words reach 143).
//   start          one-cycle pulse: compute z of one sample from the inputs below (sampled at start,
//                  hold them until done is not needed: they are registered at start)
//   f_word         F, the drive-frequency word (uint32 bit pattern)                 (channel 0)
//   t_word         T, the temperature word (int32)                                   (channel 1)
//   a0..a3         the aux words A_0..A_3 (int32; 0 where the table has fewer)       (channels 2..5)
//   k              K, the sample counter since power-on (int64, |K| <= 2^62)
//   mode           the sample's mode m (0..3) as the sequencer decided it (logged or the timer's)
//   restart        the sample's restart (OR-ed with power-on inside)
//   s              the rate stage's sum S before its clamp (int64, |S| < 2^57; firmware_ref.rate)
//   warm           the rate stage's warm-up flag of this sample
//   z_in           the external Z word (int32), used when aux_gen = 0: z = clamp(Z, +-2^30)
//   z              Q1.30 aux regressor (int32, in [-2^30, 2^30]), valid from done until next start
//   z_clamped      FLAG_AUX_CLAMPED (32) of the sample, valid with z
//   busy           high from start until done
//   done           one-cycle pulse when z, z_clamped are valid
//
// STATUS: stub (z = clamp(z_in) for every table); the generators follow.
`timescale 1ns / 1ns
module hdrg_aux (
    input  wire               clk,
    input  wire               rst,
    input  wire               we,
    input  wire [7:0]         waddr,
    input  wire [31:0]        wdata,
    input  wire               start,
    input  wire [31:0]        f_word,
    input  wire signed [31:0] t_word,
    input  wire signed [31:0] a0,
    input  wire signed [31:0] a1,
    input  wire signed [31:0] a2,
    input  wire signed [31:0] a3,
    input  wire signed [63:0] k,
    input  wire [1:0]         mode,
    input  wire               restart,
    input  wire signed [63:0] s,
    input  wire               warm,
    input  wire signed [31:0] z_in,
    output reg  signed [31:0] z,
    output reg                z_clamped,
    output reg                busy,
    output reg                done
);
    localparam signed [31:0] ONE = 32'sd1073741824;
    always @(posedge clk) begin
        if (rst) begin
            busy <= 1'b0;
            done <= 1'b0;
            z <= 32'sd0;
            z_clamped <= 1'b0;
        end else begin
            done <= 1'b0;
            if (start) begin
                done <= 1'b1;
                z <= (z_in > ONE) ? ONE : (z_in < -ONE) ? -ONE : z_in;
                z_clamped <= (z_in > ONE) || (z_in < -ONE);
            end
        end
    end
    wire unused = &{1'b0, we, waddr, wdata, f_word, t_word, a0, a1, a2, a3, k, mode, restart, s, warm};
endmodule
