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

    reg [8*LINE-1:0] line;
    reg [8*1024-1:0] cyc_path;
    integer fd, nch, p, cyc, nsamp, maxcyc, fo, i, ntok;
    reg [63:0] sumcyc;
    reg [7:0] ch;
    reg signed [63:0] val;
    reg signed [63:0] a [0:15];
    reg [31:0] last;
    reg ok, neg, quit;
    reg [8*8-1:0] cmd;

    // the next character of the line (p counts down from the first character)
    task skip_space;
        begin
            while (p >= 0 && (line[8*p +: 8] == " " || line[8*p +: 8] == "\t")) p = p - 1;
        end
    endtask
    task next_word;                           // the command word, up to 8 characters
        begin
            skip_space;
            cmd = 64'd0;
            while (p >= 0 && line[8*p +: 8] != " " && line[8*p +: 8] != "\n" && line[8*p +: 8] != "\r") begin
                cmd = {cmd[55:0], line[8*p +: 8]};
                p = p - 1;
            end
        end
    endtask
    task next_int;                            // decimal (hex = 1: hex) integer; ok = 0 at the end of the line
        input hex;
        begin
            skip_space;
            val = 64'sd0;
            ok = 1'b0;
            neg = 1'b0;
            if (p >= 0 && line[8*p +: 8] == "-") begin neg = 1'b1; p = p - 1; end
            while (p >= 0 && line[8*p +: 8] != " " && line[8*p +: 8] != "\n" && line[8*p +: 8] != "\r") begin
                ch = line[8*p +: 8];
                if (hex)
                    val = val * 16 + ((ch >= "a") ? ch - "a" + 10 : ((ch >= "A") ? ch - "A" + 10 : ch - "0"));
                else
                    val = val * 10 + (ch - "0");
                ok = 1'b1;
                p = p - 1;
            end
            if (neg) val = -val;
        end
    endtask

    task tick;
        begin
            @(posedge clk);
            #1;
        end
    endtask

    initial begin
        nsamp = 0;
        maxcyc = 0;
        sumcyc = 64'd0;
        fd = $fopen("/dev/stdin", "r");
        repeat (2) tick;
        rst = 1'b0;
        tick;
        quit = 1'b0;
        while (!quit && !$feof(fd)) begin
            line = 0;
            nch = $fgets(line, fd);
            if (nch > 0) begin
                p = nch - 1;
                next_word;
                if (cmd == "QUIT") begin
                    if ($value$plusargs("cycles=%s", cyc_path)) begin
                        fo = $fopen(cyc_path, "w");
                        $fdisplay(fo, "samples %0d max %0d sum %0d", nsamp, maxcyc, sumcyc);
                        $fclose(fo);
                    end
                    quit = 1'b1;
                end else if (cmd == "TABLE") begin
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
                    ntok = 0;
                    for (i = 0; i < 11; i = i + 1) a[i] = 64'sd0;
                    next_int(1'b0);
                    while (ok && ntok < 11) begin
                        a[ntok] = val;
                        ntok = ntok + 1;
                        next_int(1'b0);
                    end
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
                    nsamp = nsamp + 1;
                    sumcyc = sumcyc + cyc;
                    if (cyc > maxcyc) maxcyc = cyc;
                    $display("O %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d", state, vs, mode_o, sign,
                             u, v, z, s, acc, cnt, y, b, out, bias, valid, flags);
                end else if (cmd == "EVAL") begin
                    ntok = 0;
                    a[3] = 64'sd1;
                    next_int(1'b0);
                    while (ok && ntok < 4) begin
                        a[ntok] = val;
                        ntok = ntok + 1;
                        next_int(1'b0);
                    end
                    eu = a[0][31:0];
                    ev = a[1][31:0];
                    zin = a[2][31:0];
                    ebank = (a[3] == 64'sd2);
                    eval_start = 1'b1;
                    tick;
                    eval_start = 1'b0;
                    while (!done) tick;
                    $display("E %0d %0d", b, zc);
                end else if (cmd != 0)
                    $display("ERR UNSUPPORTED %0s", cmd);
            end
        end
        $finish;
    end
endmodule
