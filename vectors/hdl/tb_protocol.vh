// tb_protocol.vh - the check-impl request parser shared by the testbenches tb_top.v (hdrg_top) and
// tb_soc.v (hdrg_soc), included inside the testbench module (which declares clk and LINE): the
// request line, its command word and integers, the clock tick, the sample-request arguments and
// the cycle file of QUIT (+cycles=FILE: "samples N max M sum S", clock cycles from start to done).
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

    // up to nmax integer arguments into a[0..] (missing ones 0; a[3] = 1: EVAL's default bank);
    // ntok: how many were given
    task read_args;
        input integer nmax;
        begin
            ntok = 0;
            for (i = 0; i < 16; i = i + 1) a[i] = 64'sd0;
            a[3] = 64'sd1;
            next_int(1'b0);
            while (ok && ntok < nmax) begin
                a[ntok] = val;
                ntok = ntok + 1;
                next_int(1'b0);
            end
        end
    endtask

    task count_cycles;                        // one sample request took cyc clock cycles
        begin
            nsamp = nsamp + 1;
            sumcyc = sumcyc + cyc;
            if (cyc > maxcyc) maxcyc = cyc;
        end
    endtask

    task write_cycles;
        begin
            if ($value$plusargs("cycles=%s", cyc_path)) begin
                fo = $fopen(cyc_path, "w");
                $fdisplay(fo, "samples %0d max %0d sum %0d", nsamp, maxcyc, sumcyc);
                $fclose(fo);
            end
        end
    endtask

    task open_requests;                       // the requests come on stdin
        begin
            nsamp = 0;
            maxcyc = 0;
            sumcyc = 64'd0;
            quit = 1'b0;
            fd = $fopen("/dev/stdin", "r");
        end
    endtask

    // the next request line: cmd is its command word (0: an empty line or the end of the input);
    // QUIT writes the cycle file and sets quit
    task next_request;
        begin
            cmd = 64'd0;
            line = 0;
            nch = $fgets(line, fd);
            if (nch > 0) begin
                p = nch - 1;
                next_word;
                if (cmd == "QUIT") begin
                    write_cycles;
                    quit = 1'b1;
                end
            end
        end
    endtask
