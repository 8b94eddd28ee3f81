// hdrg_aux.v - the aux generators (firmware_ref/aux.py, FORMATS.md "Aux generators"), Verilog-2001.
//
// PORT CONTRACT (stable; the full-pipeline top hdrg_top.v instantiates this module):
//
//   clk, rst       clock; synchronous reset, active high (idle, done low, power-on state: the first
//                  sample after rst is treated as a restart, as firmware_ref.compensate's `fresh`)
//   we, waddr,     table word write, the same convention as hdrg_eval_tm.v: word index = the table
//   wdata          layout address (firmware_ref/table.py, FORMATS.md): word 45 aux_gen, words
//                  72..253 the aux parameters (72 n_terms (1..16), 73 n_chan, 74.. AF_c (ignored:
//                  units only), then 11 words per term: kind, sign, src, power, weight, c0..c5;
//                  words past the n_terms-th term, the CRC among them, are ignored).  Other
//                  addresses are ignored.  Write the whole table (aux_gen and every aux word) while
//                  idle; any write puts the generators back to power-on (next sample = restart).
//                  waddr is 8 bits (the aux words reach 253, the CRC of the longest table 254: 16
//                  terms, 4 channels, 255 words).  Write the aux words in ascending
//                  address order (n_chan before the terms, each term's kind word before its
//                  coefficients: the shift fields are decoded by kind as they arrive), as a loader
//                  streaming the table does; not in the same cycle as start.
//   start          one-cycle pulse: compute z of one sample from the inputs below (sampled at start,
//                  hold them until done is not needed: they are registered at start)
//   f_word         F, the drive-frequency word (uint32 bit pattern)                 (channel 0)
//   t_word         T, the temperature word (int32)                                   (channel 1)
//   a0..a3         the aux words A_0..A_3 (int32; 0 where the table has fewer)       (channels 2..5)
//   k              K, the sample counter since power-on (int64, |K| <= 2^62)
//   mode           the sample's mode m (0..3) as the sequencer decided it (logged or the timer's)
//   restart        the sample's restart (OR-ed with power-on inside)
//   inv            the sample's input-invalid bit (FORMATS.md "The input-invalid bit"): a filtered
//                  input term holds its state Y_j (y = RHU(Y_j, 30), op YH); a restart met on an
//                  invalid sample zeroes Y_j and is pending (pend): the input filters re-initialize
//                  at the next valid sample; decays, ramp, osc, one, rate (whose S / warm the top's
//                  estimator restarts) do not read it
//   s              the rate stage's sum S before its clamp (int64, |S| < 2^57; firmware_ref.rate)
//   warm           the rate stage's warm-up flag of this sample
//   z_in           the external Z word (int32), used when aux_gen = 0: z = clamp(Z, +-2^30)
//   z              Q1.30 aux regressor (int32, in [-2^30, 2^30]), valid from done until next start
//   z_clamped      FLAG_AUX_CLAMPED (32) of the sample, valid with z
//   busy           high from start until done
//   done           one-cycle pulse when z, z_clamped are valid
//
// WHEN z IS READY: done comes 2 + OP_CYCLES * (ops + 1) cycles after start (start and first memory
// read, OP_CYCLES per datapath operation below, the last one `FIN` writes z), ops = the sum over
// the table's terms of the operation counts in the table below: at most 16 x 13 = 208 (sixteen
// oscillators; sixteen filtered power-5 input terms: 192); aux_gen 0: 0.
//   OP_CYCLES = 2 (default): worst case 2 + 2 x 209 = 420 cycles (`sim_aux`, the fitted decay +
//     2 lags: 48; the aux vector set's other tables: docs/COST_AUX.md).  Fmax: docs/COST_AUX.md.
//   OP_CYCLES = 4 (the add and the shift registered): worst case 2 + 4 x 209 = 838 (`sim_aux` 98).
// Started together with hdrg_eval_tm (whose k7 operation Z begins 116 cycles after its start),
// z is ready in time for tables of at most 56 operations (OP_CYCLES 2) or 27 (OP_CYCLES 4).
//
// DATAPATH (time-multiplexed): ONE 32 x 32 -> 64 signed multiplier, two 64-bit adders, one 64-bit
// arithmetic right shifter and a clamp; every operation is
//
//     dest <= clamp?( (A W + C + D) >>> sh )       D: 0, 2^(rk-1) (rounding), Y_j or S
//
//   cycle X: P <= A W (A optionally negated or zeroed), CD <= C + D; the next op is decided
//   cycle Y: (P + CD) >>> sh, clamp to +-2^30 (or +-(2^31 - 1) for dX), write dest; the memories
//            read the next op's words at the end of this cycle (OP_CYCLES 4: Y is three cycles,
//            the sum and the shifted sum registered)
//
// Exactness: every operand fits 32 bits signed (split 31-bit halves where wider), every sum fits
// int64 (bounds of FORMATS.md), so the 64-bit datapath computes the reference's exact integers.
// RHUW(B, d, SB) (d up to 2^61, a 92-bit product) is two passes as firmware_ref.arith does:
// (B dh + ((B dl + 2^(SB-1)) >> 31)) >> (SB - 31) with d = dh 2^31 + dl; here on d' = -d with
// -B (the state Y is read once as the D input).  The phase kk W mod 2^64 of the oscillator is
// k0 w0 + 2^31 (k0 w1 + k1 w0) + 2^62 ((k0 w2 + k1 w1 + k2 w0 + part) mod 4) in 31-bit digits.
//
// Operations per term (restart: the state is set, not updated):
//   input    DX dX = clamp(X - REF) | Q q = clamp(RHU(dX G + OFF, SH)) | no filter: -; inv: YH
//            y = RHU(Y, 30) (held), or at a restart or pend ZSET Y = 0, YR; restart or pend: YSET
//            Y = q 2^30; else D d' = Y - q 2^30, P1, P2 (RHUW), YA Y += , YR y = RHU(Y, 30)
//            | PW g = RHU(g y, 30) power - 1 times | WT acc += w' g          2 .. 12 operations
//   rate     warm: WT (w' = 0); else R1, R2 (S against +-(2^SB - 1)), R3 sc, RP1 (G_V (sc >> 31)),
//            RP2 g = clamp(RHU(G_V sc, SH_V)) | WT                             1 or 6
//   one      ONE g = 2^30 | WT                                                   2
//   decay_on restart: DSET Y = 2^60; else D, P1, P2, YA | YR | WT                3 or 6
//   decay_exchange  m = 3 or restart: ZSET Y = 0; ex: DSET; else D, P1, P2, YA | YR | WT   3 or 6
//   ramp     RM g = K >= N ? 2^30 : RHU(K G, SH) | WT                            2
//   osc      O1, O2, O3 phase | O4 r | O5 x | O6 x^2 | H x 5 (Horner, SIN_POLY) | O12 s | WT   13
//   then     FIN z = clamp(RHU(acc, 30)) (aux_gen 0: clamp(Z))                   1
// w' = w, -w (sign and m = 2, xor osc quadrant >= 2) or 0 (sign and m = 3; rate in warm-up).
//
// Storage (up to 16 terms, formats.AUX_MAX_TERMS): the terms' 32-bit words (weight, c0..c5) in two
// 128 x 32 memories (two read ports; address {term, field}), the small fields (kind, sign, src,
// power, the shift fields) in a 16 x 22 memory (and the kinds in a 16 x 3 copy, read at the next
// term), the states Y_j in a 16 x 64 memory (Yosys on iCE40: docs/COST_AUX.md), ex_j in
// registers; the sample's inputs are registered at start.
//
// `define HDRG_BREAK_ROUNDING builds a deliberately wrong module (no rounding constants: RHU truncates).
`timescale 1ns / 1ns
module hdrg_aux #(
    parameter OP_CYCLES = 2              // cycles per operation: 2, or 4 (add and shift registered: Fmax)
) (
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
    input  wire               inv,
    input  wire signed [63:0] s,
    input  wire               warm,
    input  wire signed [31:0] z_in,
    output reg  signed [31:0] z,
    output reg                z_clamped,
    output reg                busy,
    output reg                done
);
    localparam signed [31:0] ONE = 32'sd1073741824;   // 2^30
    // SIN_POLY (formats.py): S_0..S_5
    localparam signed [31:0] S0 = 32'sd1686629713, S1 = -32'sd693598663, S2 = 32'sd85569264,
                             S3 = -32'sd5026852, S4 = 32'sd172032, S5 = -32'sd3670;

    // ---- op codes (one datapath operation each, 2 cycles) ----
    localparam [4:0] OP_DX = 5'd0, OP_Q = 5'd1, OP_YSET = 5'd2, OP_D = 5'd3, OP_P1 = 5'd4, OP_P2 = 5'd5,
                     OP_YA = 5'd6, OP_YR = 5'd7, OP_PW = 5'd8, OP_WT = 5'd9, OP_DSET = 5'd10, OP_ZSET = 5'd11,
                     OP_ONE = 5'd12, OP_R1 = 5'd13, OP_R2 = 5'd14, OP_R3 = 5'd15, OP_RP1 = 5'd16, OP_RP2 = 5'd17,
                     OP_RM = 5'd18, OP_O1 = 5'd19, OP_O2 = 5'd20, OP_O3 = 5'd21, OP_O4 = 5'd22, OP_O5 = 5'd23,
                     OP_O6 = 5'd24, OP_H = 5'd25, OP_O12 = 5'd26, OP_FIN = 5'd27, OP_YH = 5'd28;
    localparam [2:0] K_INPUT = 3'd0, K_RATE = 3'd1, K_ONE = 3'd2, K_DON = 3'd3, K_DEX = 3'd4, K_RAMP = 3'd5,
                     K_OSC = 3'd6;

    // ---- table: aux_gen, n_terms, n_chan, per-term small fields in registers; 32-bit words in RAM ----
    reg        aux_gen;
    reg [4:0]  n_terms;                  // 1..16
    reg [2:0]  n_chan;
    // per term, in a memory: {fb, fa, power, src, sign, kind}; fa: input SH (c3), rate SH_V (c2), ramp
    // SH (c2), osc part (c2); fb: input SB (c5), rate SB (c0), decay SB (c1).  A copy of the kinds
    // (read at the next term).
    reg [21:0] tf    [0:15];
    reg [2:0]  tk2   [0:15];
    reg [21:0] wst;                      // the fields of the term being written (words in address order)
    reg [31:0] ram_a  [0:127];           // {term, field}: field 0 weight, 1..6 c0..c5 (two copies:
    reg [31:0] ram_b  [0:127];           //  two read ports)
    reg [63:0] yram   [0:15];            // filter / decay state Y_j (Q1.60)
    reg [15:0] ex;                       // decay_exchange: an exchange has been seen

    // word -> (term, field) of the aux parameters: rel = waddr - 74 - n_chan = 11 wterm + wfld
    // (rel < 176: 16 terms; wfld = rel - 11 wterm, computed mod 16)
    wire [7:0] rel = waddr - 8'd74 - {5'd0, n_chan};
    reg  [3:0] wterm;
    reg  [3:0] wfld;
    integer    ti;
    always @* begin
        wterm = 4'd0;
        wfld = rel[3:0];
        for (ti = 1; ti < 16; ti = ti + 1)
            if (rel >= 8'd11 * ti[7:0]) begin
                wterm = ti[3:0];
                wfld = rel[3:0] - 4'd11 * ti[3:0];
            end
    end
    // a word of the terms 0 .. n_terms - 1 (the CRC and anything after the last term are ignored)
    wire wterm_ok = (waddr >= 8'd74 + {5'd0, n_chan}) && (rel < 8'd176) && ({1'b0, wterm} < n_terms);
    // the term's fields after this word (its kind word, field 0, comes first and clears the others)
    reg [21:0] wnew;
    always @* begin
        wnew = (wfld == 4'd0) ? {19'd0, wdata[2:0]} : wst;
        case (wfld)
            4'd1: wnew[3] = wdata[0];
            4'd2: wnew[6:4] = wdata[2:0];
            4'd3: wnew[9:7] = wdata[2:0];
            default: ;
        endcase
        case (wst[2:0])
            K_INPUT: begin
                if (wfld == 4'd8) wnew[15:10] = wdata[5:0];
                if (wfld == 4'd10) wnew[21:16] = wdata[5:0];
            end
            K_RATE: begin
                if (wfld == 4'd7) wnew[15:10] = wdata[5:0];
                if (wfld == 4'd5) wnew[21:16] = wdata[5:0];
            end
            K_DON, K_DEX: if (wfld == 4'd6) wnew[21:16] = wdata[5:0];
            default: if (wfld == 4'd7) wnew[15:10] = wdata[5:0];     // ramp SH, osc part
        endcase
    end
    always @(posedge clk) begin
        if (we) begin
            if (waddr == 8'd45) aux_gen <= wdata[0];
            if (waddr == 8'd72) n_terms <= wdata[4:0];
            if (waddr == 8'd73) n_chan <= wdata[2:0];
            if (wterm_ok) begin
                wst <= wnew;
                tf[wterm] <= wnew;
                if (wfld == 4'd0) tk2[wterm] <= wdata[2:0];
                if (wfld >= 4'd4) begin
                    ram_a[{wterm, wfld[2:0] - 3'd4}] <= wdata;     // 4 -> 0 (weight), 5..10 -> 1..6
                    ram_b[{wterm, wfld[2:0] - 3'd4}] <= wdata;
                end
            end
        end
    end

    // ---- the sample's inputs (registered at start) ----
    reg [31:0]        fq;
    reg signed [31:0] tq, a0q, a1q, a2q, a3q, zinq;
    reg [62:0]        kk;               // max(K, 0)
    reg [1:0]         mq;
    reg               rs, warmq, fresh;
    reg               irs, invq, pend;  // the input filters' restart (rs or pend), inv, a pending restart
    wire              irs_in = restart | fresh | we | pend;
    reg signed [63:0] sq;

    // ---- sequencer: op and term of the operation in flight, the next ones ----
    reg  [1:0]        ph;               // 0: X cycle (operands, multiply), then Y (add, shift, write);
                                        // OP_CYCLES 4: 1 add, 2 shift, 3 write
    reg               prime;            // the cycle after start: the memories read the first op's words
    reg [4:0]         op, nop;
    reg [3:0]         j, nj;            // term 0..15
    reg [2:0]         cnt;              // power / Horner counter
    reg               ovp, ovn, ge;     // rate clamp above / below, ramp K >= N
    reg [1:0]         quad;             // osc quadrant

    // the fields of the current op's term (read at nj: valid in its X and Y cycles, and while idle
    // those of term 0) and the kind of the term after it
    reg [21:0] tcur;
    reg [2:0]  knext;
    always @(posedge clk) begin
        tcur <= tf[nj];
        knext <= tk2[nj + 4'd1];
    end
    wire [2:0] kind = tcur[2:0];
    wire       cur_sign = tcur[3];
    wire [2:0] cur_src = tcur[6:4], cur_pow = tcur[9:7];
    wire [5:0] cur_fa = tcur[15:10], cur_fb = tcur[21:16];

    // ---- memories: synchronous reads at the next op's words (valid in its X cycle) ----
    reg [2:0] fa_sel, fb_sel;
    always @* begin
        fa_sel = 3'd0;
        fb_sel = 3'd0;
        case (nop)
            OP_DX: fa_sel = 3'd1;
            OP_Q: begin fa_sel = 3'd2; fb_sel = 3'd3; end
            OP_P1, OP_P2: fa_sel = (kind == K_INPUT) ? 3'd5 : 3'd1;   // same term
            OP_RP1, OP_RP2: fa_sel = 3'd2;
            OP_RM: begin fa_sel = 3'd2; fb_sel = 3'd1; end
            OP_O1, OP_O2, OP_O3: begin fa_sel = 3'd1; fb_sel = 3'd2; end
            default: ;
        endcase
    end
    reg [31:0] ra, rb;
    reg [63:0] yq;
    reg        ywe;
    reg [63:0] ywd;
    always @(posedge clk) begin
        ra <= ram_a[{nj, fa_sel}];
        rb <= ram_b[{nj, fb_sel}];
        yq <= yram[nj];
        if (ywe) yram[j] <= ywd;
    end

    // ---- registers of the datapath ----
    reg signed [63:0] acc, x;            // the weighted sum; the 64-bit work register
    reg signed [31:0] dxr, yv, g, cap;   // dX then q; y (osc: x); g (osc: r, p); captured half / x2
    reg signed [63:0] p, cd;             // X-cycle results: A W and C + D
    reg [5:0]         sh_q;
    reg               clamp_q, cl31_q;     // clamp to +-2^30 / to +-(2^31 - 1) (dX)

    // first op of term jj
    function [4:0] first_op;
        input [2:0] kd;
        input       exj;
        input       rsv;
        input       warmv;
        input [1:0] mv;
        begin
            case (kd)
                K_INPUT: first_op = OP_DX;
                K_RATE:  first_op = warmv ? OP_WT : OP_R1;
                K_ONE:   first_op = OP_ONE;
                K_DON:   first_op = rsv ? OP_DSET : OP_D;
                K_DEX:   first_op = (mv == 2'd3 || rsv) ? OP_ZSET : (exj ? OP_DSET : OP_D);
                K_RAMP:  first_op = OP_RM;
                default: first_op = OP_O1;
            endcase
        end
    endfunction

    // ---- operand select (X cycle) ----
    reg signed [31:0] a_op, w_op, cbv;
    reg               nega, zeroa;
    reg [3:0]         csel;
    reg [1:0]         dsel;
    reg [5:0]         rk, sh;
    reg               clamp_op, cl31;
    reg [1:0]         top2;
    localparam [3:0] C_ZERO = 4'd0, C_ACC = 4'd1, C_X = 4'd2, C_XM = 4'd3, C_XS = 4'd4, C_CB = 4'd5,
                     C_CB30 = 4'd6, C_RND = 4'd7, C_NRND = 4'd8;
    localparam [1:0] D_ZERO = 2'd0, D_RND = 2'd1, D_Y = 2'd2, D_S = 2'd3;
    wire [1:0] w1lo = {rb[0], ra[31]};
    always @* begin
        a_op = 32'sd0; w_op = 32'sd0; nega = 1'b0; zeroa = 1'b0; csel = C_ZERO; dsel = D_ZERO; cbv = 32'sd0;
        rk = 6'd0; sh = 6'd0; clamp_op = 1'b0; cl31 = 1'b0;
        top2 = ((rb[30] ? kk[1:0] : 2'd0) + (kk[32:31] * w1lo) + (kk[62] ? ra[1:0] : 2'd0) + {1'b0, cur_fa[0]});
        case (op)
            OP_DX: begin   // dX = clamp(X - REF): F and its REF offset by 2^31 (uint32 -> int32)
                a_op = {ra[31] ^ (cur_src == 3'd0), ra[30:0]}; w_op = -32'sd1; csel = C_CB; cbv = chan;
                clamp_op = 1'b1; cl31 = 1'b1;
            end
            OP_Q: begin a_op = dxr; w_op = ra; csel = C_CB; cbv = rb; dsel = D_RND; rk = cur_fa; sh = cur_fa; clamp_op = 1'b1; end
            OP_YSET: begin a_op = dxr; w_op = ONE; end
            OP_D: begin a_op = (kind == K_INPUT) ? dxr : 32'sd0; nega = 1'b1; w_op = ONE; dsel = D_Y; end
            OP_P1: begin a_op = ra; nega = 1'b1; w_op = {1'b0, x[30:0]}; dsel = D_RND; rk = cur_fb; sh = 6'd31; end
            OP_P2: begin a_op = ra; nega = 1'b1; w_op = cap; csel = C_X; sh = cur_fb - 6'd31; end
            OP_YA: begin csel = C_X; dsel = D_Y; end
            OP_YR: begin csel = C_X; dsel = D_RND; rk = 6'd30; sh = 6'd30; end
            OP_YH: begin csel = C_RND; dsel = D_Y; rk = 6'd30; sh = 6'd30; end     // the held state: RHU(Y, 30)
            OP_PW: begin a_op = g; w_op = yv; dsel = D_RND; rk = 6'd30; sh = 6'd30; end
            OP_WT: begin
                a_op = ra; w_op = g; csel = C_ACC;
                nega = (cur_sign && mq == 2'd2) ^ (kind == K_OSC && quad[1]);
                zeroa = (cur_sign && mq == 2'd3) || (kind == K_RATE && warmq);
            end
            OP_DSET: begin csel = C_CB30; cbv = ONE; end
            OP_ONE: begin csel = C_CB30; cbv = 32'sd1; end
            // rate clamp |S| <= 2^SB - 1 (rk = SB + 1: RND = 2^SB, NRND = -2^SB - 1)
            OP_R1: begin a_op = 32'sd1; w_op = 32'sd1; csel = C_NRND; dsel = D_S; rk = cur_fb + 6'd1; end  // S - 2^SB
            OP_R2: begin a_op = 32'sd1; nega = 1'b1; w_op = 32'sd1; csel = C_RND; dsel = D_S;               // S + 2^SB - 1
                         rk = cur_fb + 6'd1; end
            OP_R3: begin                                                         // sc: 2^SB - 1, 1 - 2^SB or S
                a_op = 32'sd1; nega = ~ovn; w_op = (ovp | ovn) ? 32'sd2 - {31'd0, ovp} : 32'sd0;
                csel = ovp ? C_RND : (ovn ? C_NRND : C_ZERO);
                dsel = (ovp | ovn) ? D_ZERO : D_S;
                rk = cur_fb + 6'd1;
            end
            OP_RP1: begin a_op = ra; w_op = x[62:31]; end
            OP_RP2: begin a_op = ra; w_op = cap; csel = C_XS; top2 = 2'd0; dsel = D_RND; rk = cur_fa; sh = cur_fa;
                          clamp_op = 1'b1; end
            OP_RM: begin a_op = ra; w_op = {1'b0, kk[30:0]}; dsel = D_RND; rk = cur_fa; sh = cur_fa; end
            OP_O1: begin a_op = {1'b0, rb[29:0], ra[31]}; w_op = {1'b0, kk[30:0]}; end
            OP_O2: begin a_op = {1'b0, ra[30:0]}; w_op = {1'b0, kk[61:31]}; csel = C_X; end
            OP_O3: begin a_op = {1'b0, ra[30:0]}; w_op = {1'b0, kk[30:0]}; csel = C_XS; end
            OP_O4: begin csel = C_XM; dsel = D_RND; rk = 6'd32; sh = 6'd32; end
            OP_O5: begin a_op = g; nega = quad[0]; w_op = 32'sd1; csel = quad[0] ? C_CB30 : C_ZERO; cbv = 32'sd1; end
            OP_O6: begin a_op = g; w_op = yv; dsel = D_RND; rk = 6'd30; sh = 6'd30; end
            OP_H: begin
                a_op = g; w_op = cap; csel = C_CB30; dsel = D_RND; rk = 6'd30; sh = 6'd30;
                case (cnt)
                    3'd0: cbv = S4;
                    3'd1: cbv = S3;
                    3'd2: cbv = S2;
                    3'd3: cbv = S1;
                    default: cbv = S0;
                endcase
            end
            OP_O12: begin a_op = g; w_op = yv; dsel = D_RND; rk = 6'd30; sh = 6'd30; clamp_op = 1'b1; end
            OP_FIN: begin
                clamp_op = 1'b1;
                if (aux_gen) begin csel = C_ACC; dsel = D_RND; rk = 6'd30; sh = 6'd30; end
                else begin csel = C_CB; cbv = zinq; end
            end
            default: ;   // OP_ZSET (0)
        endcase
    end

    // C, D and the rounding constant
    wire [63:0] rnd_x = (rk == 6'd0) ? 64'd0 : (64'd1 << (rk - 6'd1));        // 2^(rk-1)
    // OP_CYCLES 4: the next op's rounding constant, registered in the write-back (or prime) cycle,
    // when the memories already show the next op's term (off the X cycle's critical path)
    reg  [5:0]  rk_n;
    always @* begin
        case (nop)
            OP_Q, OP_RP2, OP_RM: rk_n = cur_fa;
            OP_P1: rk_n = cur_fb;
            OP_R1, OP_R2, OP_R3: rk_n = cur_fb + 6'd1;
            OP_YR, OP_YH, OP_PW, OP_O6, OP_H, OP_O12: rk_n = 6'd30;
            OP_O4: rk_n = 6'd32;
            OP_FIN: rk_n = aux_gen ? 6'd30 : 6'd0;
            default: rk_n = 6'd0;
        endcase
    end
    reg  [63:0] rnd_q;
    wire [63:0] rnd = (OP_CYCLES == 4) ? rnd_q : rnd_x;
    reg signed [63:0] c_val, d_val;
    always @* begin
        case (csel)
            C_ACC:  c_val = acc;
            C_X:    c_val = x;
            C_XM:   c_val = {2'b00, x[61:0]};
            C_XS:   c_val = {x[32:31] + top2, x[30:0], 31'd0};
            C_CB:   c_val = {{32{cbv[31]}}, cbv};
            C_CB30: c_val = {{2{cbv[31]}}, cbv, 30'd0};
            C_RND:  c_val = rnd;
            C_NRND: c_val = ~rnd;
            default: c_val = 64'sd0;
        endcase
        case (dsel)
`ifdef HDRG_BREAK_ROUNDING
            D_RND:  d_val = 64'sd0;          // deliberately wrong: RHU truncates
`else
            D_RND:  d_val = rnd;
`endif
            D_Y:    d_val = yq;
            D_S:    d_val = sq;
            default: d_val = 64'sd0;
        endcase
    end
    wire signed [31:0] a_eff = zeroa ? 32'sd0 : (nega ? -a_op : a_op);

    // the channel word of the term (DX): F as uint32 - 2^31, the others as they are
    reg [31:0] chan;
    always @* begin
        case (cur_src)
            3'd0: chan = {~fq[31], fq[30:0]};
            3'd1: chan = tq;
            3'd2: chan = a0q;
            3'd3: chan = a1q;
            3'd4: chan = a2q;
            default: chan = a3q;
        endcase
    end

    // the Y cycle: add, shift, clamp
    wire signed [63:0] sum = p + cd;
    reg  signed [63:0] s_r, r_r;         // OP_CYCLES 4: the sum and the shifted sum, registered
    wire signed [63:0] shr = (OP_CYCLES == 4) ? r_r : (sum >>> sh_q);
    wire               wb = (OP_CYCLES == 4) ? (ph == 2'd3) : (ph == 2'd1);     // the write-back cycle
    // above 2^30: bits 62..31 not all 0, or bit 30 and a lower one; below -2^30: bits 62..30 not
    // all 1 (negative); cl31: outside +-(2^31 - 1) (bits 62..31 not all equal to the sign; -2^31)
    wire               hi = clamp_q && !shr[63] && ((|shr[62:31]) || (!cl31_q && shr[30] && (|shr[29:0])));
    wire               lo = clamp_q && shr[63] && (!(&shr[62:31]) || (cl31_q ? !(|shr[30:0]) : !shr[30]));
    wire signed [31:0] r32 = hi ? (cl31_q ? 32'sh7fffffff : ONE) : (lo ? (cl31_q ? -32'sh7fffffff : -ONE) : shr[31:0]);

    // next op (decided in the X cycle)
    wire [4:0] term_end = ({1'b0, j} + 5'd1 >= n_terms) ? OP_FIN : first_op(knext, ex[j + 4'd1], rs, warmq, mq);
    wire [4:0] pw_or_wt = (cur_pow > 3'd1) ? OP_PW : OP_WT;
    reg  [4:0] next_op;
    always @* begin
        case (op)
            OP_DX: next_op = OP_Q;
            OP_Q: next_op = (cur_fb == 6'd0) ? pw_or_wt : (invq ? (irs ? OP_ZSET : OP_YH) : (irs ? OP_YSET : OP_D));
            OP_YH: next_op = pw_or_wt;
            OP_YSET: next_op = pw_or_wt;
            OP_D: next_op = OP_P1;
            OP_P1: next_op = OP_P2;
            OP_P2: next_op = OP_YA;
            OP_YA: next_op = OP_YR;
            OP_YR: next_op = (kind == K_INPUT) ? pw_or_wt : OP_WT;
            OP_PW: next_op = (cnt + 3'd2 >= cur_pow) ? OP_WT : OP_PW;
            OP_DSET, OP_ZSET: next_op = OP_YR;
            OP_ONE, OP_RM, OP_RP2, OP_O12: next_op = OP_WT;
            OP_R1: next_op = OP_R2;
            OP_R2: next_op = OP_R3;
            OP_R3: next_op = OP_RP1;
            OP_RP1: next_op = OP_RP2;
            OP_O1: next_op = OP_O2;
            OP_O2: next_op = OP_O3;
            OP_O3: next_op = OP_O4;
            OP_O4: next_op = OP_O5;
            OP_O5: next_op = OP_O6;
            OP_O6: next_op = OP_H;
            OP_H: next_op = (cnt == 3'd4) ? OP_O12 : OP_H;
            OP_WT: next_op = term_end;
            default: next_op = OP_FIN;
        endcase
    end

    always @* begin
        ywe = 1'b0;
        ywd = 64'sd0;
        if (busy && wb && !prime) begin
            case (op)
                OP_YSET, OP_YA, OP_DSET, OP_ZSET: begin ywe = 1'b1; ywd = shr; end
                default: ;
            endcase
        end
    end

    always @(posedge clk) begin
        done <= 1'b0;
        if (rst) begin
            busy <= 1'b0;
            fresh <= 1'b1;
            pend <= 1'b0;
            z <= 32'sd0;
            z_clamped <= 1'b0;
            ph <= 2'd0;
            prime <= 1'b0;
            ex <= 16'd0;
            nop <= OP_FIN;
            nj <= 4'd0;
        end else if (!busy) begin
            if (we) begin fresh <= 1'b1; pend <= 1'b0; end
            if (start) begin
                busy <= 1'b1;
                prime <= 1'b1;
                fq <= f_word; tq <= t_word; a0q <= a0; a1q <= a1; a2q <= a2; a3q <= a3; zinq <= z_in;
                kk <= k[63] ? 63'd0 : k[62:0];
                mq <= mode;
                rs <= restart | fresh | we;
                irs <= irs_in;
                invq <= inv;
                pend <= inv & irs_in;
                fresh <= 1'b0;
                warmq <= warm;
                sq <= s;
                acc <= 64'sd0;
                nj <= 4'd0;
                nop <= aux_gen ? first_op(kind, ex[0], restart | fresh | we, warm, mode) : OP_FIN;
                ph <= 2'd0;
            end
        end else if (prime) begin
            rnd_q <= (rk_n == 6'd0) ? 64'd0 : (64'd1 << (rk_n - 6'd1));
            // the first op: needs rs, warmq, mq registered (this cycle), the memories read its words
            prime <= 1'b0;
            op <= nop;
            j <= nj;
        end else if (ph == 2'd0) begin
            // X cycle
            p <= a_eff * w_op;
            cd <= c_val + d_val;
            sh_q <= sh;
            clamp_q <= clamp_op;
            cl31_q <= cl31;
            nop <= next_op;
            nj <= (op == OP_WT) ? j + 4'd1 : ((op == OP_FIN) ? 4'd0 : j);   // idle: term 0
            case (op)
                OP_DX: cnt <= 3'd0;
                OP_P1: cap <= x[62:31];
                OP_RP1: cap <= {1'b0, x[30:0]};
                OP_RM: ge <= (kk[62:31] != 32'd0) || ({1'b0, kk[30:0]} >= rb);
                default: ;
            endcase
            ph <= 2'd1;
        end else if (!wb) begin
            // OP_CYCLES 4: the add, then the shift
            if (ph == 2'd1) s_r <= sum;
            else r_r <= s_r >>> sh_q;
            ph <= ph + 2'd1;
        end else begin
            // Y cycle: write back
            rnd_q <= (rk_n == 6'd0) ? 64'd0 : (64'd1 << (rk_n - 6'd1));
            case (op)
                OP_DX: dxr <= r32;
                OP_Q: begin dxr <= r32; yv <= r32; g <= r32; end
                OP_D, OP_P1, OP_P2, OP_YA, OP_DSET, OP_ZSET, OP_R3, OP_RP1, OP_O1, OP_O2, OP_O3: x <= shr;
                OP_YR, OP_YH: begin yv <= shr[31:0]; g <= shr[31:0]; end
                OP_PW: begin g <= shr[31:0]; cnt <= cnt + 3'd1; end
                OP_WT: acc <= shr;
                OP_ONE, OP_RP2, OP_O12: g <= r32;
                OP_RM: g <= ge ? ONE : shr[31:0];
                OP_R1: ovp <= ~shr[63];
                OP_R2: ovn <= shr[63];
                OP_O4: begin g <= shr[31:0]; quad <= x[63:62]; end
                OP_O5: begin yv <= shr[31:0]; g <= shr[31:0]; end
                OP_O6: begin cap <= shr[31:0]; g <= S5; cnt <= 3'd0; end
                OP_H: begin g <= shr[31:0]; cnt <= cnt + 3'd1; end
                OP_FIN: begin z <= r32; z_clamped <= hi | lo; end
                default: ;
            endcase
            if (op == OP_ZSET) ex[j] <= (mq == 2'd3);
            if (op == OP_DSET) ex[j] <= 1'b0;
            if (op == OP_FIN) begin
                busy <= 1'b0;
                done <= 1'b1;
            end
            op <= nop;
            j <= nj;
            ph <= 2'd0;
        end
    end
endmodule
