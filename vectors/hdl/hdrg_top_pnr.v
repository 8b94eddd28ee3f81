// hdrg_top_pnr.v - a pin-light wrapper of hdrg_top for place-and-route (Fmax, fit on an UP5K): the
// inputs (overlapping fields: every input bit is driven) arrive through a 192-bit serial shift register (sdi, shift), and every output bit of the
// sample (the 16 O fields, B, z_clamped) is XOR-folded into a registered 16-bit word on pins, so
// that synthesis keeps the whole pipeline.  Not part of a real design (the fold is not decodable).
`timescale 1ns / 1ns
module hdrg_top_pnr #(
    parameter N_HIST = 64
) (
    input  wire        clk,
    input  wire        rst,
    input  wire        sdi,
    input  wire        shift,
    input  wire        we,          // write table word sr[31:0] at address sr[39:32]
    input  wire        load,
    input  wire        start,       // f sr[31:0], t sr[63:32], r sr[95:64], z sr[127:96]; mode sr[33:32] ...
    input  wire        eval_start,  // u sr[159:128], v sr[191:160]
    output wire        busy,
    output reg         done_q,
    output reg  [15:0] fold_q
);
    reg [191:0] sr;
    wire [2:0] state;
    wire [7:0] vs, flags;
    wire [1:0] mode_o;
    wire signed [1:0] sign;
    wire signed [31:0] u, v, z, out, bias;
    wire signed [63:0] s, acc, y, b;
    wire [30:0] cnt;
    wire valid, zc, done, fits;
    always @(posedge clk)
        if (shift) sr <= {sr[190:0], sdi};
    hdrg_top #(.N_HIST(N_HIST)) top (
        .clk(clk), .rst(rst), .we(we), .waddr(sr[39:32]), .wdata(sr[31:0]), .load(load), .start(start),
        .eval_start(eval_start), .f(sr[31:0]), .t(sr[63:32]), .r(sr[95:64]), .mode(sr[33:32]), .self_timed(sr[34]),
        .restart(sr[35]), .invalid(sr[38]), .zin(sr[127:96]), .a0(sr[159:128]), .a1(sr[191:160]), .a2(sr[95:64]), .a3(sr[63:32]),
        .kin(sr[191:128]), .k_given(sr[37]), .eval_u(sr[159:128]), .eval_v(sr[191:160]), .eval_bank(sr[36]),
        .state(state), .vs(vs), .mode_o(mode_o), .sign(sign), .u(u), .v(v), .z(z), .s(s), .acc(acc), .cnt(cnt),
        .y_hold(y), .b(b), .out_hold(out), .bias_hold(bias), .valid(valid), .flags(flags), .z_clamped(zc),
        .busy(busy), .done(done), .table_fits(fits));
    wire [639:0] all = {state, vs, flags, mode_o, sign, u, v, z, out, bias, s, acc, y, b, cnt, valid, zc, fits, 167'd0};
    integer i;
    reg [15:0] fold;
    always @* begin
        fold = 16'd0;
        for (i = 0; i < 40; i = i + 1)
            fold = fold ^ all[16*i +: 16];
    end
    always @(posedge clk) begin
        done_q <= done;
        fold_q <= fold;
    end
endmodule
