// tb_soc.v - hdrg_soc (the C twin on a RISC-V core) behind the check-impl stdin/stdout protocol,
// like tb_top.v for hdrg_top (the request parser: tb_protocol.vh), so that
//     hdrg vectors check-impl --cmd "vvp -n tb_soc.vvp"        (Icarus: iverilog -g2005)
//     hdrg vectors check-impl --cmd "obj_dir/Vtb_soc"          (Verilator 5: --binary)
// run the vector sets on the SoC.  Requests: TABLE, S, EVAL, QUIT (tb_top.v); each writes its
// inputs into the mailbox through the host port, pulses the command and reads the results
// (hdrg_soc_main.c has the mailbox layout).  Answers: "T <n> <CRC word>" (or "ERR TABLE <return
// code> word <index>" for a table the firmware refuses: the C twin checks the header, the fields
// and the CRC), "O <16 fields>", "E <B> <zclamped>" ("ERR NOTABLE" before a table is loaded);
// anything else "ERR UNSUPPORTED".  A trap of
// the core ends the run with "ERR TRAP".  +cycles=FILE: tb_top.v's cycle file (start to done).
// The firmware image: `HDRG_SOC_ROM (hdrg_soc.v).
`timescale 1ns / 1ns
module tb_soc;
    parameter LINE = 4096;                    // longest request line (characters)
    parameter ROM_WORDS = 3072;               // hdrg_soc's ROM (the firmware link script's)
    localparam ARG = 256, OUT = 272;          // mailbox words (hdrg_soc_main.c)
    localparam NOTABLE = 255;                 // a result's return code: no table loaded (hdrg_soc_main.c)

    reg clk = 1'b0, rst = 1'b1, we = 1'b0, re = 1'b0, load = 1'b0, start = 1'b0, eval_start = 1'b0;
    reg [8:0] addr = 9'd0;
    reg [31:0] wdata = 32'd0;
    wire [31:0] rdata;
    wire busy, done, trap;

    hdrg_soc #(.ROM_WORDS(ROM_WORDS)) dut (.clk(clk), .rst(rst), .we(we), .re(re), .addr(addr), .wdata(wdata), .rdata(rdata),
                  .load(load), .start(start), .eval_start(eval_start), .busy(busy), .done(done), .trap(trap));

    always #5 clk = ~clk;

    `include "tb_protocol.vh"

    reg [31:0] w [0:31];                      // the results read back

    task put;                                 // mailbox word ad <- d
        input integer ad;
        input [31:0] d;
        begin
            addr = ad[8:0];
            wdata = d;
            we = 1'b1;
            tick;
            we = 1'b0;
        end
    endtask
    task get;                                 // w[0..n-1] <- mailbox words OUT..OUT+n-1
        input integer n;
        integer j;
        begin
            for (j = 0; j < n; j = j + 1) begin
                addr = OUT + j;
                re = 1'b1;
                tick;
                re = 1'b0;
                w[j] = rdata;
            end
        end
    endtask
    task run;                                 // pulse a command (0 load, 1 start, 2 eval) and wait for done
        input integer which;
        begin
            load = which == 0;
            start = which == 1;
            eval_start = which == 2;
            tick;
            load = 1'b0;
            start = 1'b0;
            eval_start = 1'b0;
            cyc = 1;
            while (!done && !trap) begin tick; cyc = cyc + 1; end
            if (trap) begin
                $display("ERR TRAP the core trapped");
                $finish;
            end
        end
    endtask

    initial begin
        open_requests;
        repeat (2) tick;
        rst = 1'b0;
        while (busy && !trap) tick;           // booting: busy until the firmware's first done
        while (!quit && !$feof(fd)) begin
            next_request;
            if (quit || cmd == 0)
                ;                             // QUIT, or nothing on the line
            else if (cmd == "TABLE") begin
                ntok = 0;
                next_int(1'b1);
                while (ok) begin
                    put(ntok, val[31:0]);
                    ntok = ntok + 1;
                    next_int(1'b1);
                end
                put(ARG, ntok);
                run(0);
                get(3);
                if (w[0] == 0)
                    $display("T %0d %08x", ntok, w[2]);
                else
                    $display("ERR TABLE %0d word %0d", w[0], w[1]);
            end else if (cmd == "S") begin
                read_args(11);
                for (i = 0; i < 6; i = i + 1) put(ARG + i, a[i][31:0]);
                put(ARG + 6, a[6][31:0]);                   // K
                put(ARG + 7, a[6][63:32]);
                put(ARG + 8, ntok > 6);                     // K given
                for (i = 0; i < 4; i = i + 1) put(ARG + 9 + i, a[7 + i][31:0]);
                run(1);
                count_cycles;
                get(21);
                if (w[0] == NOTABLE)
                    $display("ERR NOTABLE send TABLE first");
                else if (w[0] != 0)
                    $display("ERR INPUT %0d", w[0]);
                else
                    $display("O %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d",
                             w[1], w[2], w[3], $signed(w[4]), $signed(w[5]), $signed(w[6]), $signed(w[7]),
                             $signed({w[9], w[8]}), $signed({w[11], w[10]}), w[12], $signed({w[14], w[13]}),
                             $signed({w[16], w[15]}), $signed(w[17]), $signed(w[18]), w[19], w[20]);
            end else if (cmd == "EVAL") begin
                read_args(4);
                for (i = 0; i < 4; i = i + 1) put(ARG + i, a[i][31:0]);
                run(2);
                get(4);
                if (w[0] == NOTABLE)
                    $display("ERR NOTABLE send TABLE first");
                else
                    $display("E %0d %0d", $signed({w[2], w[1]}), w[3]);
            end else
                $display("ERR UNSUPPORTED %0s", cmd);
        end
        $finish;
    end
endmodule
