// hdrg_soc.v - the whole per-sample pipeline as the C twin (firmware_ref/c/hdrg_fw.c, unchanged) on
// a RISC-V core: the small-area build for the iCE40 UP5K (docs/COST.md "iCE40 UP5K: the C twin
// on a RISC-V core").  It trades cycles for area: every stage (table load and checks, sequencer,
// proxy, rate, aux generators, evaluator, combiner, output words and flags) is the firmware
// firmware_ref/c/rv32/hdrg_soc_main.c running on PicoRV32 (RV32IMC; the pythondata-cpu-picorv32
// package, ISC licence), so the SoC computes exactly what the C twin computes.
//
// Memories: ROM (the firmware image, ROM_WORDS x 32 in EBR, written by the bitstream: $readmemh of
// `HDRG_SOC_ROM; in simulation +rom=FILE), RAM (64 KiB: two SB_SPRAM256KA side by side; behavioural when not synthesized):
// the mailbox, the state (hdrg_state_t, 18.5 kB with a 4,096-word ring) and the stack.  CPU address
// map: ROM 0x00000-0x0ffff, RAM 0x10000-0x1ffff, command register 0x20000.
//
// Host port (one word per clock; not while busy): we writes wdata at mailbox word addr, re reads
// mailbox word addr into rdata (valid on the next clock only: the RAM reads for the core after it).
// The mailbox (words of the RAM from 0x10000; the firmware's header comment has the layout): 0..255
// the table words, 256..271 a command's inputs, 272..303 its results.  A command is a one-clock
// pulse, sent only while busy is low: load (the table; its word count in word 256), start (a
// sample), eval_start (the evaluator alone); busy is high from the next clock until the firmware
// has written the results; done pulses one clock when it has.  After reset busy is high until the
// firmware has booted (about 106,000 clocks: it zeroes its state), and done pulses once then.  The
// host has priority on the RAM: a firmware access waits while we or re is high.  The core's trap (an illegal instruction or a misaligned access of a broken firmware)
// holds it and raises trap.
`timescale 1ns / 1ns
`ifndef HDRG_SOC_ROM
`define HDRG_SOC_ROM "hdrg_soc_rom.hex"
`endif
module hdrg_soc #(
    parameter ROM_WORDS = 3072              // 12 KiB (24 EBR); the firmware link script's ROM
) (
    input  wire        clk,
    input  wire        rst,
    input  wire        we,
    input  wire        re,
    input  wire [8:0]  addr,
    input  wire [31:0] wdata,
    output wire [31:0] rdata,
    input  wire        load,
    input  wire        start,
    input  wire        eval_start,
    output wire        busy,
    output reg         done,
    output wire        trap
);
    wire        mem_valid;
    /* verilator lint_off UNUSEDSIGNAL */
    wire        mem_instr;                  // fetches and data accesses are answered alike
    wire [31:0] mem_addr;                   // 0x00000-0x2ffff decoded; bits 1:0 are 0 for word accesses
    /* verilator lint_on UNUSEDSIGNAL */
    wire [31:0] mem_wdata;
    wire [3:0]  mem_wstrb;
    reg         mem_ready;
    reg  [31:0] mem_rdata;

    picorv32 #(
        .ENABLE_COUNTERS(0), .ENABLE_COUNTERS64(0), .ENABLE_REGS_16_31(1), .ENABLE_REGS_DUALPORT(1),
        .LATCHED_MEM_RDATA(1), .TWO_CYCLE_COMPARE(1), .TWO_CYCLE_ALU(1), .TWO_STAGE_SHIFT(1), .BARREL_SHIFTER(0), .COMPRESSED_ISA(1), .CATCH_MISALIGN(1),
        .CATCH_ILLINSN(1), .ENABLE_PCPI(0), .ENABLE_MUL(0), .ENABLE_FAST_MUL(1), .ENABLE_DIV(1),
        .ENABLE_IRQ(0), .PROGADDR_RESET(32'h0000_0000)
    ) cpu (
        .clk(clk), .resetn(!rst), .trap(trap),
        .mem_valid(mem_valid), .mem_instr(mem_instr), .mem_ready(mem_ready), .mem_addr(mem_addr),
        .mem_wdata(mem_wdata), .mem_wstrb(mem_wstrb), .mem_rdata(mem_rdata),
        .pcpi_wr(1'b0), .pcpi_rd(32'd0), .pcpi_wait(1'b0), .pcpi_ready(1'b0), .irq(32'd0)
    );

    // the address decode of a pending access (mem_valid until mem_ready)
    wire pend    = mem_valid && !mem_ready;
    wire sel_ram = mem_addr[17:16] == 2'd1;
    wire sel_cmd = mem_addr[17:16] == 2'd2;
    wire host    = we || re;
    reg  issued;
    wire issue   = pend && !issued && !(sel_ram && host);

    // ROM: synchronous read, the firmware image
    localparam ROM_AW = $clog2(ROM_WORDS);  // word address bits (an address past the image reads X / 0)
    reg [31:0] rom [0:ROM_WORDS-1];
    reg [31:0] rom_q;
`ifdef SYNTHESIS
    initial $readmemh(`HDRG_SOC_ROM, rom);
`else
    reg [8*1024-1:0] rom_path;                  // simulation: +rom=FILE overrides the image
    initial begin
        if (!$value$plusargs("rom=%s", rom_path))
            rom_path = `HDRG_SOC_ROM;
        $readmemh(rom_path, rom);
    end
`endif
    always @(posedge clk)
        rom_q <= rom[mem_addr[ROM_AW+1:2]];

    // RAM: 16 K x 32, byte writes; the host's access first
    wire [13:0] ram_a  = host ? {5'd0, addr} : mem_addr[15:2];
    wire [31:0] ram_d  = host ? wdata : mem_wdata;
    wire [3:0]  ram_we = host ? {4{we}} : ((issue && sel_ram) ? mem_wstrb : 4'd0);
    wire [31:0] ram_q;
    hdrg_soc_ram ram (.clk(clk), .a(ram_a), .d(ram_d), .we(ram_we), .q(ram_q));
    assign rdata = ram_q;

    // the command register: set by a host pulse, cleared by the firmware's write (done); booted: the
    // firmware's first write (after its start-up)
    reg [1:0] cmd;
    reg booted;
    wire cmd_write = issue && sel_cmd && mem_wstrb != 4'd0;
    always @(posedge clk) begin
        booted <= !rst && (booted || cmd_write);
        if (rst)
            cmd <= 2'd0;
        else if (load)
            cmd <= 2'd1;
        else if (start)
            cmd <= 2'd2;
        else if (eval_start)
            cmd <= 2'd3;
        else if (cmd_write)
            cmd <= 2'd0;
        done <= !rst && cmd_write;
    end
    assign busy = !booted || cmd != 2'd0;

    // the core's bus: an access is issued on the clock it is seen (a RAM access waits while the host
    // uses the RAM), its read word registered on the next and handed to the core with mem_ready on
    // the one after (two clocks per access: the memories' read data reach only a register, not the
    // core's instruction decoder, within a clock)
    reg [1:0] src;
    always @(posedge clk) begin
        issued <= !rst && issue;
        mem_ready <= !rst && issued;
        src <= mem_addr[17:16];
        if (issued)                         // held until the next access (LATCHED_MEM_RDATA)
            case (src)
                2'd0: mem_rdata <= rom_q;
                2'd1: mem_rdata <= ram_q;
                default: mem_rdata <= {30'd0, cmd};
            endcase
    end
endmodule
