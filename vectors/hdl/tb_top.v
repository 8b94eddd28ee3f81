// tb_top.v - hdrg_top behind the check-impl stdin/stdout protocol (firmware_ref/c/README.md; the
// C driver hdrg_fw_main.c is the other implementation), so that
//     hdrg vectors check-impl --cmd "vvp -n tb_top.vvp"        (Icarus: iverilog -g2001)
//     hdrg vectors check-impl --cmd "obj_dir/Vtb_top"          (Verilator 5: --binary)
// run the vector sets on the RTL.  Requests (one per line on stdin):
//   TABLE <hex word> ...      write every word through the table port, pulse load; "T <n> <last word>"
//                             (the last word is the CRC word: the RTL does not check it, the host does)
//   S F T R MODE RESTART Z [K A0..A3]   one sample (MODE -1: self-timed; RESTART bit 0 restart, bit 1
//                             the input-invalid bit); "O <16 fields>"
//   EVAL U V Z [BANK]         the evaluator alone; "E <B> <zclamped>"
//   QUIT                      end
// anything else: "ERR UNSUPPORTED <request>".  +cycles=FILE writes "samples N max M sum S" (clock
// cycles from start to done, per sample request).  N_HIST: the ring depth of hdrg_top.
`timescale 1ns / 1ns
module tb_top;
    parameter N_HIST = 4096;
    parameter LINE = 4096;                    // longest request line (characters)

    reg clk = 1'b0, rst = 1'b1, we = 1'b0, load = 1'b0, start = 1'b0, eval_start = 1'b0;
    wire table_fits;
    reg [7:0] waddr = 8'd0;
    reg [31:0] wdata = 32'd0, f = 32'd0;
    reg signed [31:0] t = 0, r = 0, zin = 0, eu = 0, ev = 0, a0 = 0, a1 = 0, a2 = 0, a3 = 0;
    reg signed [63:0] kin = 0;
    reg k_given = 1'b0;
    reg [1:0] mode = 2'd0;
    reg self_timed = 1'b0, restart = 1'b0, invalid = 1'b0, ebank = 1'b0;
    wire [2:0] state;
    wire [7:0] vs, flags;
    wire [1:0] mode_o;
    wire signed [1:0] sign;
    wire signed [31:0] u, v, z, out, bias;
    wire signed [63:0] s, acc, y, b;
    wire [30:0] cnt;
    wire valid, zc, busy, done;

    hdrg_top #(.N_HIST(N_HIST)) dut (
        .clk(clk), .rst(rst), .we(we), .waddr(waddr), .wdata(wdata), .load(load), .start(start),
        .eval_start(eval_start), .f(f), .t(t), .r(r), .mode(mode), .self_timed(self_timed), .restart(restart), .invalid(invalid),
        .zin(zin), .a0(a0), .a1(a1), .a2(a2), .a3(a3), .kin(kin), .k_given(k_given), .eval_u(eu), .eval_v(ev), .eval_bank(ebank), .state(state), .vs(vs), .mode_o(mode_o),
        .sign(sign), .u(u), .v(v), .z(z), .s(s), .acc(acc), .cnt(cnt), .y_hold(y), .b(b), .out_hold(out),
        .bias_hold(bias), .valid(valid), .flags(flags), .z_clamped(zc), .busy(busy), .done(done),
        .table_fits(table_fits));

    always #5 clk = ~clk;

    `include "tb_protocol.vh"

    initial begin
        open_requests;
        repeat (2) tick;
        rst = 1'b0;
        tick;
        while (!quit && !$feof(fd)) begin
            next_request;
            if (quit || cmd == 0)
                ;                             // QUIT, or nothing on the line
            else if (cmd == "TABLE") begin
                ntok = 0;
                next_int(1'b1);
                while (ok) begin
                    waddr = ntok[7:0];
                    wdata = val[31:0];
                    last = val[31:0];
                    we = 1'b1;
                    tick;
                    we = 1'b0;
                    ntok = ntok + 1;
                    next_int(1'b1);
                end
                load = 1'b1;
                tick;
                load = 1'b0;
                if (table_fits)
                    $display("T %0d %08x", ntok, last);
                else
                    $display("ERR FIELD word 9 rate_n: the window is longer than this build's ring (N_HIST %0d)", N_HIST);
            end else if (cmd == "S") begin
                read_args(11);
                f = a[0][31:0];
                t = a[1][31:0];
                r = a[2][31:0];
                self_timed = (a[3] < 0);
                mode = a[3][1:0];
                restart = a[4][0];
                invalid = a[4][1];                // RESTART bit 1: the input-invalid bit
                zin = a[5][31:0];
                kin = a[6];
                k_given = (ntok > 6);
                a0 = a[7][31:0];
                a1 = a[8][31:0];
                a2 = a[9][31:0];
                a3 = a[10][31:0];
                start = 1'b1;
                tick;
                start = 1'b0;
                cyc = 1;
                while (!done) begin tick; cyc = cyc + 1; end
                count_cycles;
                $display("O %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d", state, vs, mode_o, sign,
                         u, v, z, s, acc, cnt, y, b, out, bias, valid, flags);
            end else if (cmd == "EVAL") begin
                read_args(4);
                eu = a[0][31:0];
                ev = a[1][31:0];
                zin = a[2][31:0];
                ebank = (a[3] == 64'sd2);
                eval_start = 1'b1;
                tick;
                eval_start = 1'b0;
                while (!done) tick;
                $display("E %0d %0d", b, zc);
            end else
                $display("ERR UNSUPPORTED %0s", cmd);
        end
        $finish;
    end
endmodule
