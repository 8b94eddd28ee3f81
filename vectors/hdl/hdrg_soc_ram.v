// hdrg_soc_ram.v - the RAM of hdrg_soc (vectors/hdl/hdrg_soc.v): 16 K x 32 with byte writes (we: one
// bit per byte) and a registered read (q: the word at the previous clock's address).  Synthesized:
// two SB_SPRAM256KA (16 K x 16, nibble write masks); simulated: a behavioural array.
`timescale 1ns / 1ns
module hdrg_soc_ram (
    input  wire        clk,
    input  wire [13:0] a,
    input  wire [31:0] d,
    input  wire [3:0]  we,
    output wire [31:0] q
);
`ifdef SYNTHESIS
    SB_SPRAM256KA lo (.ADDRESS(a), .DATAIN(d[15:0]), .MASKWREN({we[1], we[1], we[0], we[0]}), .WREN(|we[1:0]),
                      .CHIPSELECT(1'b1), .CLOCK(clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
                      .DATAOUT(q[15:0]));
    SB_SPRAM256KA hi (.ADDRESS(a), .DATAIN(d[31:16]), .MASKWREN({we[3], we[3], we[2], we[2]}), .WREN(|we[3:2]),
                      .CHIPSELECT(1'b1), .CLOCK(clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
                      .DATAOUT(q[31:16]));
`else
    reg [31:0] mem [0:16383];
    reg [31:0] qr;
    always @(posedge clk) begin
        if (we[0]) mem[a][7:0] <= d[7:0];
        if (we[1]) mem[a][15:8] <= d[15:8];
        if (we[2]) mem[a][23:16] <= d[23:16];
        if (we[3]) mem[a][31:24] <= d[31:24];
        qr <= mem[a];
    end
    assign q = qr;
`endif
endmodule
