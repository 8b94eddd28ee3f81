// hdrg_top.v - the whole per-sample pipeline of firmware_ref/FORMATS.md ("The exact integer
// algorithm") in synthesizable Verilog-2001: table load, sequencer (self-timed timer or logged
// modes), proxy, rate estimator, aux word, evaluator, combiner / residual tracker (combine_first:
// ftr, pair, trend; regress_first: pair, trend, none), output words and flags.  Bit-exact with
// firmware_ref/compensate.py (Pipeline.step) and the C twin; checked by tb_top.v through the
// check-impl protocol (host_tools/bench/cost_rtl.py).
//
// Table load: write word k of the table layout (FORMATS.md) through (we, waddr, wdata), then pulse
// `load` (power-on state: timer, rate ring and counters, combiner, holds).  Used words: 3..14 proxy
// and rate, 16..21 combiner and timer, 22..44 and 49..71 the evaluator's banks, 45 aux_gen, 47
// order, 48 n_banks.  The header checks and the CRC are the loader's job (host side): not here.
//
// Per sample: inputs on `start` (one-cycle pulse; do not pulse while busy): f (F word), t (T word),
// r (rate word), mode (0..3, ignored when self_timed), self_timed, restart, invalid (the
// input-invalid bit, FORMATS.md "The input-invalid bit": the sample is not valid, flag 64; the rate
// estimator restarts at it and at the next sample (prev_inv); it taints its mode-1/2 window, which
// is then not committed (taint); the aux input filters hold their state over it), zin (the Z
// word; aux_gen 0).  Outputs valid with `done` (held until the next sample).  `eval_start` evaluates
// (eval_u, eval_v, zin, eval_bank) alone (the evaluator vectors): b, z_clamped with `done`.
//
// Schedule (clock cycles from `start`; one 32 x 32 multiplier in the evaluator, shared with the
// front-end ALU hdrg_alu, which also uses the evaluator's rounding adder and shifter while the
// evaluator is idle (6 cycles per operation: r = RHU(a w + c, sh), a up to 59 bits in two passes);
// the aux generators' own multiplier; a 44-step restoring divider hdrg_div (no multiplier)):
//   1      latch; 3 timer (S_TM: its 3 state passes, one per cycle); 1 ring write + read of the
//          word n back, combiner restart / age / window switch; the divider starts the closing
//          window's mean
//   ALU    [lsq: n x_out, (n - 1) A'] or [iir: RHU((d << 24) - y, e), the gear e = min(shift,
//          floor(log2 k))], then [v: RHU(S G_V, SH_V)]
//          unless warm-up, then [u: RHU(dP G_U + U_OFF, SH_U)]: 1..4 operations x 6 cycles
//   126    evaluator (hdrg_eval_tm: 25 operations x 5 cycles) on u, v, z, bank
//          in parallel: mean division (47), slope division (47), commit, then the trend term
//          RHU(slope d, 16) on the ALU (6, after the front end has released it)
//   2      tail: residual r = symsat32(RHU(c 2^11 - B, 11)) (order 1), window sum, y, OUT, BIAS, flags
// lsq in O(1): A = sum of the window's words, Q = sum of age x word (age 0 = present); per sample
// Q' = Q + A - n x_out, A' = A - x_out + P (x_out = the word n back, 0 until the ring holds it), and
// S = (n - 1) A' - 2 Q' = sum_j (2j - (n - 1)) (P_j - P) exactly (the weights sum to zero).
// Worst case measured by tb_top over every vector: the RESULT line's cycles.
//
// N_HIST: ring depth (longest diffn/lsq window n; the firmware allows 4096, the vectors use less);
// a table with a longer window drives `table_fits` low: the controller refuses it.
// `define HDRG_BREAK_ROUNDING builds a deliberately wrong pipeline (the ALU and evaluator truncate).
`timescale 1ns / 1ns
module hdrg_top #(
    parameter N_HIST = 4096
) (
    input  wire               clk,
    input  wire               rst,
    input  wire               we,
    input  wire [7:0]         waddr,
    input  wire [31:0]        wdata,
    input  wire               load,
    input  wire               start,
    input  wire               eval_start,
    input  wire [31:0]        f,
    input  wire signed [31:0] t,
    input  wire signed [31:0] r,
    input  wire [1:0]         mode,
    input  wire               self_timed,
    input  wire               restart,
    input  wire               invalid,     // the input-invalid bit of the sample
    input  wire signed [31:0] zin,
    input  wire signed [31:0] a0,          // aux words A_0..A_3 (aux_gen 1)
    input  wire signed [31:0] a1,
    input  wire signed [31:0] a2,
    input  wire signed [31:0] a3,
    input  wire signed [63:0] kin,         // K, the sample counter (when k_given; else the internal count)
    input  wire               k_given,
    input  wire signed [31:0] eval_u,
    input  wire signed [31:0] eval_v,
    input  wire               eval_bank,
    output reg  [2:0]         state,
    output reg  [7:0]         vs,
    output reg  [1:0]         mode_o,
    output reg  signed [1:0]  sign,
    output reg  signed [31:0] u,
    output reg  signed [31:0] v,
    output reg  signed [31:0] z,
    output reg  signed [63:0] s,
    output reg  signed [63:0] acc,
    output reg  [30:0]        cnt,
    output wire signed [63:0] y_hold,     // |y| < 2^47 (FORMATS.md): a 49-bit register
    output wire signed [63:0] b,
    output reg  signed [31:0] out_hold,
    output reg  signed [31:0] bias_hold,
    output reg                valid,
    output reg  [7:0]         flags,
    output wire               z_clamped,
    output reg                busy,
    output reg                done,
    output wire               table_fits   // the loaded table's window n fits the ring (n <= N_HIST)
);
    localparam [30:0] CMAX = 31'h7fffffff;                    // COUNT_MAX
    localparam signed [63:0] SLOPE_MAX = 64'sd1099511627775;  // 2^40 - 1
    localparam [33:0] D_MAX = 34'd4194303;                    // 2^22 - 1
    localparam AW = 13;
    localparam signed [63:0] K_LIMIT = 64'sd4611686018427387904;   // 2^62

    // ---- table fields ----
    reg        kind;
    reg [31:0] p_ref_w, warmup, power_on_n, exchange_n, dwell_n, settle_n, max_stale_n;
    reg signed [31:0] g_u, u_off, g_v;
    reg [5:0]  sh_u, sh_v, sb;
    reg [1:0]  est, combiner;
    reg [12:0] n_tab;
    reg [4:0]  ishift;
    reg        order, two_banks;
    always @(posedge clk)
        if (we)
            case (waddr)
                8'd3:  kind <= wdata[0];
                8'd4:  p_ref_w <= wdata;
                8'd5:  g_u <= wdata;
                8'd6:  u_off <= wdata;
                8'd7:  sh_u <= wdata[5:0];
                8'd8:  est <= wdata[1:0];
                8'd9:  n_tab <= wdata[12:0];
                8'd10: ishift <= wdata[4:0];
                8'd11: warmup <= wdata;
                8'd12: sb <= wdata[5:0];
                8'd13: g_v <= wdata;
                8'd14: sh_v <= wdata[5:0];
                8'd16: combiner <= wdata[1:0];
                8'd17: settle_n <= wdata;
                8'd18: max_stale_n <= wdata;
                8'd19: power_on_n <= wdata;
                8'd20: exchange_n <= wdata;
                8'd21: dwell_n <= wdata;
                8'd47: order <= wdata[0];
                8'd48: two_banks <= (wdata == 32'd2);
                default: ;
            endcase
    wire [12:0] n = (est == 2'd1 || est == 2'd2) ? n_tab : 13'd1;
    // a table whose diffn/lsq window is longer than this build's ring would read and write the ring
    // out of range (wrong rates, no flag): table_fits is low for it, and the controller must refuse
    // the table (the testbench answers ERR FIELD, as the C twin does for a window above 4096)
    assign table_fits = ({19'd0, n} <= N_HIST);
    // k saturates at max(warmup, 2^shift) for iir (the gear reads k up to 2^shift), else at warmup
    wire [31:0] ksat = (est == 2'd3 && (32'd1 << ishift) > warmup) ? (32'd1 << ishift) : warmup;
    wire ftr = (combiner == 2'd0);

    function signed [63:0] pval;           // proxy word -> value (freq: uint32, temp: int32)
        input [31:0] w;
        input kd;
        pval = kd ? {{32{w[31]}}, w} : {32'd0, w};
    endfunction
    // clamps by bit tests (no 64-bit comparators): above / below the bound
    /* verilator lint_off UNUSEDSIGNAL */
    function above30;                      // x > 2^30
        input signed [63:0] x;
        above30 = !x[63] && ((|x[62:31]) || (x[30] && (|x[29:0])));
    endfunction
    function below30;                      // x < -2^30
        input signed [63:0] x;
        below30 = x[63] && !(&x[62:30]);
    endfunction
    function signed [31:0] clamp1;         // clamp to +-2^30 (the result fits 32 bits)
        input signed [63:0] x;
        clamp1 = above30(x) ? 32'sd1073741824 : (below30(x) ? -32'sd1073741824 : x[31:0]);
    endfunction
    function above31;                      // x > 2^31 - 1
        input signed [63:0] x;
        above31 = !x[63] && (|x[62:31]);
    endfunction
    function below31;                      // x < -(2^31 - 1)
        input signed [63:0] x;
        below31 = x[63] && (!(&x[62:31]) || !(|x[30:0]));
    endfunction
    /* verilator lint_on UNUSEDSIGNAL */
    function [4:0] gear;                   // the iir's shift min(sh, floor(log2 kk)), kk >= 1
        input [31:0] kk;
        input [4:0] sh;
        integer j;
        begin
            gear = 5'd0;
            for (j = 1; j < 25; j = j + 1)
                if (|(kk >> j)) gear = j[4:0];
            if (gear > sh) gear = sh;
        end
    endfunction
    function signed [31:0] symsat32;       // clamp to +-(2^31 - 1)
        input signed [63:0] x;
        symsat32 = above31(x) ? 32'sh7fffffff : (below31(x) ? -32'sh7fffffff : x[31:0]);
    endfunction
    function sat32;                        // symsat32(x) != x
        input signed [63:0] x;
        sat32 = above31(x) || below31(x);
    endfunction

    // ---- sequencer: timer and state tables ----
    reg [2:0]  tstate;
    reg [31:0] tcnt;
    function [31:0] slen;                  // state length (FTR: never left)
        input [2:0] st;
        case (st)
            3'd0: slen = power_on_n;
            3'd1, 3'd3: slen = exchange_n;
            3'd2, 3'd4: slen = dwell_n;
            default: slen = 32'hffffffff;
        endcase
    endfunction
    function [2:0] snext;
        input [2:0] st;
        snext = (st == 3'd0) ? (ftr ? 3'd5 : 3'd1) : ((st == 3'd4) ? 3'd1 : st + 3'd1);
    endfunction
    // the timer's three passes, one per clock cycle (S_TM; restart: from power-on): tsr, tcr
    reg [2:0] tsr;
    reg [31:0] tcr;
    reg [1:0] tpass;
    reg [1:0] last_window;
    reg [2:0] st_now;
    reg [1:0] m_now;
    // latched sample inputs
    reg [31:0] f_q;
    reg signed [31:0] t_q, r_q, z_q, a0_q, a1_q, a2_q, a3_q;
    reg signed [63:0] k_q, kc;
    wire signed [63:0] k_in = k_given ? kin : kc;
    reg [1:0] mode_q;
    reg self_q, restart_q, inv_q;
    reg prev_inv;                      // the previous sample was input-invalid (power-on: 0; not reset at restarts)
    wire rr = restart_q || inv_q || prev_inv;   // the rate estimator's restart
    wire [2:0] ts_in = (tpass == 2'd0) ? (restart_q ? 3'd0 : tstate) : tsr;
    wire [31:0] tc_in = (tpass == 2'd0) ? (restart_q ? 32'd0 : tcnt) : tcr;
    wire t_adv = ts_in != 3'd5 && tc_in >= slen(ts_in);
    wire [2:0] ts3 = tsr;
    wire [31:0] tc3 = tcr;
    always @* begin
        if (self_q) begin
            st_now = ts3;
            case (ts3)
                3'd2: m_now = 2'd1;
                3'd4: m_now = 2'd2;
                3'd5: m_now = 2'd0;
                default: m_now = 2'd3;
            endcase
        end else begin
            m_now = mode_q;
            case (mode_q)
                2'd0: st_now = 3'd5;
                2'd1: st_now = 3'd2;
                2'd2: st_now = 3'd4;
                default: st_now = (last_window == 2'd1) ? 3'd3 : 3'd1;
            endcase
        end
    end

    // ---- front end: ring, rate state ----
    reg [31:0] ring [0:N_HIST];
    reg [AW-1:0] head;
    reg [12:0] fill;                   // words before the present one in the segment, up to n
    reg [31:0] k;
    reg signed [63:0] iy, la, lq;      // iir state; lsq A and Q
    reg signed [63:0] s_w;             // the rate sum S of the sample
    reg [31:0] rd_w;
    reg [12:0] fill_p;
    reg [31:0] k_p;
    reg warm_q;
    wire [AW-1:0] head_n = rr ? {AW{1'b0}} : ((head == n) ? {AW{1'b0}} : head + 1'b1);
    wire [AW-1:0] rd_addr = (head_n == n) ? {AW{1'b0}} : head_n + 1'b1;     // the word n back
    wire signed [63:0] pv = pval(kind ? t_q : f_q, kind);
    wire signed [63:0] xo = pval(rd_w, kind);

    // ---- the front-end ALU ----
    reg alu_go;
    reg signed [63:0] alu_a, alu_c;
    reg signed [31:0] alu_w;
    reg [5:0] alu_sh;
    wire signed [63:0] alu_r;
    wire alu_done;
    wire signed [31:0] mul_a, mul_w;
    wire signed [63:0] mul_p;
    wire signed [63:0] rnd_sum, rnd_s;
    wire [5:0] rnd_sh;
    hdrg_alu alu (.clk(clk), .start(alu_go), .a(alu_a), .w(alu_w), .c(alu_c), .sh(alu_sh), .r(alu_r), .done(alu_done),
                  .ma(mul_a), .mw(mul_w), .mp(mul_p), .xsum(rnd_sum), .xsh(rnd_sh), .xs(rnd_s));

    // ---- evaluator ----
    reg ev_go, ev_bank;
    reg signed [31:0] ev_u, ev_v, ev_z;
    /* verilator lint_off UNUSEDSIGNAL */
    wire ev_busy;                       // the top's own busy covers it
    /* verilator lint_on UNUSEDSIGNAL */
    wire ev_done;
    // ---- aux generators: z (aux_gen 1: the generator terms; aux_gen 0: clamp(Z)) ----
    reg aux_go, aux_fin, evo;
    wire signed [31:0] aux_z;
    wire aux_zc, aux_done;
    /* verilator lint_off UNUSEDSIGNAL */
    wire aux_busy;                      // the top's own busy covers it
    /* verilator lint_on UNUSEDSIGNAL */
    hdrg_aux aux (.clk(clk), .rst(rst), .we(we), .waddr(waddr), .wdata(wdata), .start(aux_go), .f_word(f_q), .t_word(t_q),
                  .a0(a0_q), .a1(a1_q), .a2(a2_q), .a3(a3_q), .k(k_q), .mode(mode_o), .restart(restart_q), .inv(inv_q), .s(s_w),
                  .warm(warm_q), .z_in(z_q), .z(aux_z), .z_clamped(aux_zc), .busy(aux_busy), .done(aux_done));

    hdrg_eval_tm #(.Z_LATE(1)) ev (.clk(clk), .rst(rst), .we(we && waddr < 8'd72), .waddr(waddr[6:0]), .wdata(wdata), .start(ev_go),
                     .bank(ev_bank), .u(ev_u), .v(ev_v), .z(evo ? ev_z : aux_z), .b(b), .z_clamped(z_clamped), .busy(ev_busy),
                     .done(ev_done), .xa(mul_a), .xw(mul_w), .xp(mul_p), .xsum(rnd_sum), .xsh(rnd_sh), .xs(rnd_s), .zhold(!evo && !aux_fin && !aux_done));

    // ---- combiner state ----
    reg [1:0] cur, ccur;
    reg [30:0] pos, age1, age2, span1, span2, sp_q;
    reg [1:0] nc1, nc2;
    // widths from FORMATS.md: |W| < 2^41 (the divider's quotient: |q| < 2^44, 45 bits), |slope| <= 2^40 - 1,
    // |W + T| < 2^47, |y| < 2^47, |B| < 2^52
    reg signed [44:0] w1, w2, mean_q;
    reg signed [41:0] slope1, slope2;
    reg signed [48:0] other, y_r;
    assign y_hold = {{15{y_r[48]}}, y_r};
    reg use_q, sat_c, have_other;
    reg taint;                         // the open window held an input-invalid sample: not committed
    reg div_go;
    reg signed [63:0] div_a;
    reg [35:0] div_b;
    reg [4:0] div_k;
    wire signed [63:0] div_q;
    wire div_ovf, div_done;
    hdrg_div dv (.clk(clk), .start(div_go), .a(div_a), .b(div_b), .k(div_k), .q(div_q), .ovf(div_ovf), .done(div_done));

    // ---- control ----
    localparam S_IDLE = 4'd0, S_T = 4'd1, S_F = 4'd2, S_ALU = 4'd3, S_EV = 4'd4, S_T1 = 4'd5, S_T2 = 4'd6,
               S_EVO = 4'd7, S_TM = 4'd12;
    localparam O_L1 = 3'd0, O_L2 = 3'd1, O_I = 3'd2, O_V = 3'd3, O_U = 3'd4, O_END = 3'd5;
    localparam C_IDLE = 3'd0, C_DIV1 = 3'd1, C_DIV2 = 3'd2, C_COMMIT = 3'd3, C_OTHER = 3'd4, C_TREND = 3'd5,
               C_READY = 3'd6;
    reg [3:0] ph;
    reg [2:0] op, cph;
    reg ev_fin;
    reg signed [63:0] nx;
    reg vc_q, uc_q;

    // ring n back valid for lsq; iir input
    wire signed [63:0] xout = (fill_p >= n) ? xo : 64'sd0;
    wire signed [63:0] la_n = la - xout + pv;                     // A' (la, lq: previous, restart-cleared)
    wire signed [63:0] dd24 = (pv - xo) <<< 24;
    // S clamp for v
    // smax = 2^SB - 1 as a mask; S > smax: a bit above SB; S < -smax: negative and not (the bits
    // above SB all ones and the bits below not all zero)
    wire [63:0] smask = ~({64{1'b1}} << sb);
    wire s_hi = !s_w[63] && (|(s_w & ~smask));
    wire s_lo = s_w[63] && ((|(~s_w & ~smask)) || !(|(s_w & smask)));
    wire signed [63:0] s_cl = s_hi ? smask : (s_lo ? ((sb == 6'd0) ? 64'sd0 : {~smask[63:1], 1'b1}) : s_w);
    wire signed [63:0] dpr = pv - pval(p_ref_w, kind);
    wire signed [31:0] dpc = symsat32(dpr);
    // combiner helpers
    wire [1:0] o_mode = 2'd3 - cur;
    wire [30:0] age_o = (o_mode == 2'd1) ? age1 : age2;
    wire [30:0] span_o = (o_mode == 2'd1) ? span1 : span2;
    wire [1:0] nc_o = (o_mode == 2'd1) ? nc1 : nc2;
    wire signed [44:0] w_o = (o_mode == 2'd1) ? w1 : w2;
    wire signed [44:0] w_c = (ccur == 2'd1) ? w1 : w2;
    wire signed [41:0] slope_o = (o_mode == 2'd1) ? slope1 : slope2;
    wire [33:0] d_raw = {2'b0, age_o, 1'b0} + {3'b0, span_o};
    wire signed [55:0] bn = b[55:0];                              // |B| < 2^52
    wire signed [32:0] r33 = {r_q[31], r_q};
    wire signed [32:0] c0 = (cur == 2'd1) ? r33 : -r33;
    wire signed [56:0] c57 = {{13{c0[32]}}, c0, 11'd0}, b57 = {bn[55], bn}, y57 = {{8{y_r[48]}}, y_r};
    wire signed [56:0] rxn = (c57 - b57 + 57'sd1024) >>> 11;
    wire signed [63:0] rx = {{7{rxn[56]}}, rxn};
    wire signed [31:0] c1 = symsat32(rx);
    wire signed [32:0] cc = order ? {c1[31], c1} : c0;
    wire signed [56:0] yon = ((order ? y57 : y57 - b57) + 57'sd1024) >>> 11;
    wire signed [56:0] bon = (b57 + 57'sd1024) >>> 11;
    wire signed [63:0] yo = {{7{yon[56]}}, yon}, bo = {{7{bon[56]}}, bon};
    wire signed [31:0] yo_s = symsat32(yo), bo_s = symsat32(bo);

    always @(posedge clk) begin
        done <= 1'b0;
        alu_go <= 1'b0;
        ev_go <= 1'b0;
        div_go <= 1'b0;
        if (rst || load) begin
            ph <= S_IDLE;
            busy <= 1'b0;
            cph <= C_IDLE;
            tstate <= 3'd0; tcnt <= 32'd0;
            kc <= 64'sd0; evo <= 1'b0; prev_inv <= 1'b0; taint <= 1'b0;
            head <= {AW{1'b0}}; fill <= 13'd0; k <= 32'd0; iy <= 64'sd0; la <= 64'sd0; lq <= 64'sd0;
            cur <= 2'd0; acc <= 64'sd0; cnt <= 31'd0; pos <= 31'd0; nc1 <= 2'd0; nc2 <= 2'd0;
            w1 <= 45'sd0; w2 <= 45'sd0; slope1 <= 42'sd0; slope2 <= 42'sd0;
            span1 <= 31'd0; span2 <= 31'd0; age1 <= 31'd0; age2 <= 31'd0; last_window <= 2'd0;
            y_r <= 49'sd0; out_hold <= 32'sd0; bias_hold <= 32'sd0;
        end else begin
            // ---------------- the combiner's window commit (parallel to the front end and evaluator)
            case (cph)
                C_DIV1: if (div_done) begin
                    mean_q <= div_q[44:0];
                    if ((ccur == 2'd1 ? nc1 : nc2) != 2'd0) begin
                        div_a <= div_q - {{19{w_c[44]}}, w_c};
                        div_b <= age_q_dc2(ccur == 2'd1 ? age1 : age2, sp_q, ccur == 2'd1 ? span1 : span2);
                        div_k <= 5'd16;
                        div_go <= 1'b1;
                        cph <= C_DIV2;
                    end else
                        cph <= C_COMMIT;
                end
                C_DIV2: if (div_done) begin
                    if (div_ovf || (!div_q[63] && (|div_q[62:40])) || (div_q[63] && (!(&div_q[62:40]) || !(|div_q[39:0])))) begin   // |q| > SLOPE_MAX
                        sat_c <= 1'b1;
                        if (ccur == 2'd1) slope1 <= (div_ovf ? div_a[63] : div_q[63]) ? -SLOPE_MAX[41:0] : SLOPE_MAX[41:0];
                        else slope2 <= (div_ovf ? div_a[63] : div_q[63]) ? -SLOPE_MAX[41:0] : SLOPE_MAX[41:0];
                    end else if (ccur == 2'd1) slope1 <= div_q[41:0];
                    else slope2 <= div_q[41:0];
                    cph <= C_COMMIT;
                end
                C_COMMIT: begin
                    if (ccur == 2'd1) begin
                        w1 <= mean_q; span1 <= sp_q; age1 <= 31'd1; nc1 <= (nc1 == 2'd0) ? 2'd1 : 2'd2;
                    end else begin
                        w2 <= mean_q; span2 <= sp_q; age2 <= 31'd1; nc2 <= (nc2 == 2'd0) ? 2'd1 : 2'd2;
                    end
                    cph <= C_OTHER;
                end
                C_OTHER: begin
                    have_other <= nc_o != 2'd0 && {1'b0, age_o} <= max_stale_n;
                    other <= {{4{w_o[44]}}, w_o};
                    if (use_q && !ftr && combiner == 2'd2 && !(order && warm_q) && nc_o != 2'd0
                        && {1'b0, age_o} <= max_stale_n)
                        cph <= C_TREND;
                    else
                        cph <= C_READY;
                end
                C_TREND: if (ev_fin) begin
                    // the ALU (the evaluator's multiplier) is free once the evaluator is done
                    if (|d_raw[33:22]) sat_c <= 1'b1;                  // d_raw > D_MAX
                    alu_a <= {{22{slope_o[41]}}, slope_o};
                    alu_w <= (|d_raw[33:22]) ? D_MAX[31:0] : d_raw[31:0];
                    alu_c <= 64'sd0;
                    alu_sh <= 6'd16;
                    alu_go <= 1'b1;
                    cph <= C_IDLE + 3'd7;       // wait state (7)
                end
                3'd7: if (alu_done) begin
                    other <= other + alu_r[48:0];
                    cph <= C_READY;
                end
                default: ;
            endcase

            aux_go <= 1'b0;
            if (ev_done) ev_fin <= 1'b1;
            if (aux_done) aux_fin <= 1'b1;
            case (ph)
                S_IDLE: begin
                    if (start) begin
                        f_q <= f; t_q <= t; r_q <= r; z_q <= zin; mode_q <= mode; self_q <= self_timed;
                        a0_q <= a0; a1_q <= a1; a2_q <= a2; a3_q <= a3;
                        // K: given, or the internal count (kc = min(K + 1, 2^62) after each sample)
                        k_q <= k_in;
                        kc <= (!k_in[63] && k_in[62]) ? K_LIMIT : k_in + 64'sd1;      // k_in >= 2^62
                        evo <= 1'b0;
                        restart_q <= restart;
                        inv_q <= invalid;
                        busy <= 1'b1;
                        tpass <= 2'd0;
                        ph <= S_TM;
                    end else if (eval_start) begin
                        ev_u <= eval_u; ev_v <= eval_v; ev_z <= zin; ev_bank <= eval_bank;
                        evo <= 1'b1;
                        ev_go <= 1'b1;
                        busy <= 1'b1;
                        ph <= S_EVO;
                    end
                end
                S_TM: begin                     // one timer pass per cycle
                    tsr <= t_adv ? snext(ts_in) : ts_in;
                    tcr <= t_adv ? 32'd0 : tc_in;
                    tpass <= tpass + 2'd1;
                    if (tpass == 2'd2) ph <= S_T;
                end
                S_EVO: if (ev_done) begin
                    busy <= 1'b0;
                    done <= 1'b1;
                    ph <= S_IDLE;
                end
                S_T: begin
                    // sequencer
                    state <= st_now;
                    mode_o <= m_now;
                    case (st_now)
                        3'd0, 3'd1: begin vs <= 8'h01; sign <= 2'sd0; end
                        3'd2: begin vs <= 8'h05; sign <= 2'sd1; end
                        3'd3: begin vs <= 8'h02; sign <= 2'sd0; end
                        3'd4: begin vs <= 8'h1a; sign <= -2'sd1; end
                        default: begin vs <= 8'h05; sign <= 2'sd1; end
                    endcase
                    if (self_q) begin
                        tstate <= ts3;
                        tcnt <= (ts3 != 3'd5) ? tc3 + 32'd1 : tc3;
                    end
                    // rate: ring write, read of the word n back, counters (rr: a new segment; a
                    // restart, an invalid sample or the one after it)
                    ring[head_n] <= kind ? t_q : f_q;
                    rd_w <= ring[rd_addr];
                    head <= head_n;
                    fill_p <= rr ? 13'd0 : fill;
                    fill <= rr ? ((n == 13'd0) ? 13'd0 : 13'd1) : ((fill >= n) ? n : fill + 13'd1);
                    k_p <= rr ? 32'd0 : k;
                    warm_q <= (rr ? 32'd0 : k) < warmup;
                    k <= ((rr ? 32'd0 : k) < ksat) ? (rr ? 32'd0 : k) + 32'd1 : (rr ? 32'd0 : k);
                    if (rr) begin iy <= 64'sd0; la <= 64'sd0; lq <= 64'sd0; end
                    prev_inv <= inv_q;
                    // combiner: restart, ages, window switch (the closing window's commit starts here)
                    sat_c <= 1'b0;
                    use_q <= 1'b0;
                    have_other <= 1'b0;
                    cph <= C_READY;
                    if (!ftr) begin
                        age1 <= (age1 == CMAX) ? CMAX : age1 + 31'd1;
                        age2 <= (age2 == CMAX) ? CMAX : age2 + 31'd1;
                        if (restart_q) begin
                            nc1 <= 2'd0; nc2 <= 2'd0; slope1 <= 42'sd0; slope2 <= 42'sd0;
                        end
                        if (m_now != (restart_q ? 2'd0 : cur)) begin
                            if (!restart_q && cur != 2'd0 && cnt != 31'd0 && !taint) begin
                                ccur <= cur;
                                sp_q <= cnt - 31'd1;
                                div_a <= acc;
                                div_b <= {5'd0, cnt};
                                div_k <= 5'd10;
                                div_go <= 1'b1;
                                cph <= C_DIV1;
                            end else
                                cph <= C_OTHER;
                            cur <= (m_now == 2'd1 || m_now == 2'd2) ? m_now : 2'd0;
                            if (m_now == 2'd1 || m_now == 2'd2) last_window <= m_now;
                            acc <= 64'sd0; cnt <= 31'd0; pos <= 31'd0;
                            taint <= (m_now == 2'd1 || m_now == 2'd2) && inv_q;
                            if ((m_now == 2'd1 || m_now == 2'd2) && settle_n == 32'd0)
                                use_q <= !inv_q;
                            else if (m_now == 2'd1 || m_now == 2'd2)
                                pos <= 31'd1;
                        end else begin
                            cph <= C_OTHER;
                            if (restart_q) begin cur <= 2'd0; acc <= 64'sd0; cnt <= 31'd0; end
                            taint <= (!restart_q && taint) || ((m_now == 2'd1 || m_now == 2'd2) && inv_q);
                            if (m_now == 2'd1 || m_now == 2'd2) begin
                                if ({1'b0, (restart_q ? 31'd0 : pos)} >= settle_n)
                                    use_q <= !inv_q;
                                else
                                    pos <= (restart_q ? 31'd0 : pos) + 31'd1;
                            end else if (restart_q)
                                pos <= 31'd0;
                        end
                    end
                    ev_fin <= 1'b0;
                    aux_fin <= 1'b0;
                    ph <= S_F;
                    op <= (est == 2'd2) ? O_L1 : ((est == 2'd3) ? O_I : O_V);
                end
                S_F: begin
                    // the next front-end ALU operation (or its skip)
                    ph <= S_ALU;
                    case (op)
                        O_L1: begin alu_a <= xout; alu_w <= {19'd0, n}; alu_c <= 64'sd0; alu_sh <= 6'd0; alu_go <= 1'b1; end
                        O_L2: begin alu_a <= la_n; alu_w <= {19'd0, n} - 32'sd1; alu_c <= 64'sd0; alu_sh <= 6'd0;
                                    alu_go <= 1'b1; end
                        O_I: begin
                            if (k_p >= 32'd2) begin
                                alu_a <= dd24 - iy; alu_w <= 32'sd1; alu_c <= 64'sd0; alu_sh <= {1'b0, gear(k_p, ishift)};
                                alu_go <= 1'b1;
                            end else begin
                                if (k_p == 32'd1) begin iy <= dd24; s_w <= dd24; end else s_w <= iy;
                                op <= O_V; ph <= S_F;
                            end
                        end
                        O_V: begin
                            if (est == 2'd0 || est == 2'd1)
                                s_w <= (k_p >= {19'd0, n}) ? pv - xo : 64'sd0;
                            op <= O_U;
                            ph <= S_F;
                            v <= 32'sd0;
                            vc_q <= 1'b0;
                            if (!warm_q) begin
                                op <= O_V;
                                ph <= S_ALU + 4'd8;     // one cycle for s_w, then issue V
                            end
                        end
                        O_U: begin aux_go <= 1'b1;      // S and warm are final: start the aux generators
                                   alu_a <= {{32{dpc[31]}}, dpc}; alu_w <= g_u; alu_c <= {{32{u_off[31]}}, u_off}; alu_sh <= sh_u;
                                   alu_go <= 1'b1; end
                        default: begin
                            // front end done: start the evaluator
                            ev_u <= u; ev_v <= v; ev_z <= z_q; ev_bank <= two_banks && mode_o == 2'd2;
                            ev_go <= 1'b1;
                            ph <= S_EV;
                        end
                    endcase
                end
                4'd11: begin                    // issue V (S clamped)
                    alu_a <= s_cl; alu_w <= g_v; alu_c <= 64'sd0; alu_sh <= sh_v; alu_go <= 1'b1;
                    ph <= S_ALU;
                end
                S_ALU: if (alu_done) begin
                    ph <= S_F;
                    case (op)
                        O_L1: begin nx <= alu_r; op <= O_L2; end
                        O_L2: begin
                            la <= la_n;
                            lq <= lq + la - nx;
                            s_w <= (k_p + 32'd1 >= {19'd0, n}) ? alu_r - ((lq + la - nx) <<< 1) : 64'sd0;
                            op <= O_V;
                        end
                        O_I: begin iy <= iy + alu_r; s_w <= iy + alu_r; op <= O_V; end
                        O_V: begin
                            vc_q <= s_hi || s_lo || above30(alu_r) || below30(alu_r);
                            v <= clamp1(alu_r);
                            op <= O_U;
                        end
                        default: begin          // O_U
                            uc_q <= above30(alu_r) || below30(alu_r);
                            u <= clamp1(alu_r);
                            op <= O_END;
                        end
                    endcase
                end
                S_EV: if ((ev_done || ev_fin) && cph == C_READY) begin
                    s <= s_w;
                    if (warm_q) begin v <= 32'sd0; vc_q <= 1'b0; end
                    z <= aux_z;
                    ph <= S_T1;
                end
                S_T1: begin
                    // combiner tail (reads B): window sum, y
                    valid <= 1'b0;
                    if (ftr) begin
                        y_r <= {{6{r_q[31]}}, r_q, 11'd0};
                        valid <= 1'b1;
                    end else if (use_q && !(order && warm_q)) begin
                        if (order && sat32(rx)) sat_c <= 1'b1;
                        if (cnt != CMAX) begin acc <= acc + {{31{cc[32]}}, cc}; cnt <= cnt + 31'd1; end
                        else sat_c <= 1'b1;
                        if (order && combiner == 2'd3) begin
                            y_r <= {{6{c1[31]}}, c1, 11'd0};
                            valid <= 1'b1;
                        end else if (have_other) begin
                            y_r <= {{6{cc[32]}}, cc, 10'd0} + other;
                            valid <= 1'b1;
                        end
                    end
                    ph <= S_T2;
                end
                default: begin                  // S_T2: outputs, flags (valid holds cvalid here)
                    flags <= {(sat_c || (valid && !warm_q && mode_o != 2'd3 && !inv_q && (sat32(yo) || sat32(bo)))),
                              inv_q, aux_zc, !valid && mode_o != 2'd3, mode_o == 2'd3, warm_q, vc_q && !warm_q, uc_q};
                    if (valid && !warm_q && mode_o != 2'd3 && !inv_q) begin
                        out_hold <= yo_s;
                        bias_hold <= bo_s;
                    end
                    valid <= valid && !warm_q && mode_o != 2'd3 && !inv_q;
                    busy <= 1'b0;
                    done <= 1'b1;
                    ph <= S_IDLE;
                end
            endcase
        end
    end

    function [35:0] age_q_dc2;              // dc2 = 2 (age - 1) - sp + span (>= 2)
        input [30:0] ag;
        input [30:0] sp;
        input [30:0] spn;
        age_q_dc2 = {4'd0, ag, 1'b0} - 36'd2 - {5'd0, sp} + {5'd0, spn};
    endfunction
endmodule
