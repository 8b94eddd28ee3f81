// hdrg_front.v - proxy and rate stages of the fixed-point pipeline (firmware_ref/FORMATS.md steps
// 2 and 3; firmware_ref/proxy.py, rate.py; the C twin's proxy_u / rate_step), Verilog-2001.
//
// One sample per `start` pulse (pw = the proxy word: the F word of a freq table as uint32, the T
// word of a temp table as int32; restart = 1 at the start of a gap-free segment):
//
//   proxy:  dP = clamp(P - p_ref, +-(2^31 - 1));  u = clamp(RHU(dP g_u + u_off, sh_u), +-2^30)   uc
//   rate:   the ring of the last n + 1 words (n = rate_n for diffn/lsq, 1 for diff/iir); k counts
//           samples since restart up to the warm-up W;
//           diff/diffn  S = P - P[n back]                               (k >= n, else 0)
//           lsq         S = sum_j (2j - (n - 1)) (P[n-1-j back] - P)    (k >= n - 1, else 0)
//           iir         y = (P - P[1 back]) 2^24 at k = 1, y += RHU((P - P[1 back]) 2^24 - y, shift)
//                       at k >= 2; S = y
//           warm = k < W (then v = 0, k += 1); else v = clamp(RHU(clamp(S, +-(2^SB - 1)) g_v, sh_v),
//           +-2^30), vc = either clamp
//
// Schedule: cycle 0 writes the ring and starts the read of the oldest needed word; diff/diffn/iir
// finish in 4 cycles; lsq reads one ring word per cycle (n + 4 cycles).  Products: dP g_u (33 x 32),
// (2j - n + 1)(P_j - P) (13 x 34), clamp(S) g_v (56 x 32) - written as `*`, mapped by synthesis.
// Table: write words 3..14 of the table layout (FORMATS.md) through (we, waddr, wdata), then
// pulse `clear` (power-on reset of the ring; N_HIST + 1 cycles).  N_HIST: longest lsq/diffn window.
`timescale 1ns / 1ns
module hdrg_front #(
    parameter N_HIST = 4096
) (
    input  wire               clk,
    input  wire               we,
    input  wire [5:0]         waddr,
    input  wire [31:0]        wdata,
    input  wire               clear,        // power-on reset of the rate state (after a table load)
    input  wire               start,
    input  wire [31:0]        pw,           // the proxy word (bit pattern)
    input  wire               restart,
    output reg  signed [31:0] u,
    output reg                uc,
    output reg  signed [31:0] v,
    output reg                vc,
    output reg  signed [63:0] s,
    output reg                warm,
    output reg                busy,
    output reg                done
);
    localparam signed [63:0] ONE = 64'sd1073741824;     // 2^30
    localparam signed [63:0] I32 = 64'sd2147483647;     // 2^31 - 1
    localparam AW = 13;                                 // ring address bits (N_HIST + 1 <= 8192)

    // ---- table fields ----
    reg        kind;                    // 0 freq (uint32), 1 temp (int32)
    reg [31:0] p_ref_w;
    reg signed [31:0] g_u, u_off, g_v;
    reg [5:0]  sh_u, sh_v, sb;
    reg [1:0]  est;
    reg [12:0] n_tab;
    reg [4:0]  ishift;
    reg [31:0] warmup;
    always @(posedge clk) begin
        if (we)
            case (waddr)
                6'd3:  kind <= wdata[0];
                6'd4:  p_ref_w <= wdata;
                6'd5:  g_u <= wdata;
                6'd6:  u_off <= wdata;
                6'd7:  sh_u <= wdata[5:0];
                6'd8:  est <= wdata[1:0];
                6'd9:  n_tab <= wdata[12:0];
                6'd10: ishift <= wdata[4:0];
                6'd11: warmup <= wdata;
                6'd12: sb <= wdata[5:0];
                6'd13: g_v <= wdata;
                6'd14: sh_v <= wdata[5:0];
                default: ;
            endcase
    end

    // proxy word -> value (freq: unsigned, temp: signed)
    function signed [63:0] pval;
        input [31:0] w;
        input k;
        begin
            pval = k ? {{32{w[31]}}, w} : {32'd0, w};
        end
    endfunction

    function signed [63:0] rhu;
        input signed [63:0] x;
        input [5:0] sh;
        begin
            if (sh == 6'd0)
                rhu = x;
            else
`ifdef HDRG_BREAK_ROUNDING
                rhu = x >>> sh;
`else
                rhu = (x + (64'sd1 <<< (sh - 6'd1))) >>> sh;
`endif
        end
    endfunction

    // ---- rate state ----
    reg [31:0] ring [0:N_HIST];          // n + 1 <= N_HIST + 1 words used
    reg [AW-1:0] head, rd_addr, clr_addr;
    reg [31:0] k;
    reg signed [63:0] iy, p, acc, pr;
    reg [31:0] prev_w;
    reg [12:0] n, j;
    reg [31:0] rd_w;
    reg [2:0]  ph;
    reg        clearing;

    wire [12:0] n_eff = (est == 2'd1 || est == 2'd2) ? n_tab : 13'd1;

    // ring index m back from h (0 <= m <= n)
    function [AW-1:0] back;
        input [AW-1:0] h;
        input [12:0] m;
        input [12:0] nn;
        begin
            back = (h >= m) ? h - m : h + nn + 13'd1 - m;
        end
    endfunction

    reg signed [63:0] dp, sc, vv, uu;
    reg sclamp;
    always @(posedge clk) begin
        done <= 1'b0;
        if (clear) begin
            clearing <= 1'b1;
            clr_addr <= 0;
            busy <= 1'b1;
            head <= 0;
            k <= 32'd0;
            iy <= 64'sd0;
            n <= n_eff;
        end else if (clearing) begin
            ring[clr_addr] <= 32'd0;
            clr_addr <= clr_addr + 1'b1;
            if (clr_addr == N_HIST) begin
                clearing <= 1'b0;
                busy <= 1'b0;
            end
        end else if (!busy) begin
            if (start) begin
                busy <= 1'b1;
                ph <= 3'd0;
                p <= pval(pw, kind);
                // restart: k = 0, head = 0, y = 0; else advance the head
                if (restart) begin
                    head <= 0;
                    k <= 32'd0;
                    iy <= 64'sd0;
                    ring[0] <= pw;
                    rd_addr <= back(0, (est == 2'd2) ? n - 13'd1 : n, n);
                end else begin
                    head <= (head == n) ? 0 : head + 1'b1;
                    ring[(head == n) ? 0 : head + 1'b1] <= pw;
                    rd_addr <= back((head == n) ? 0 : head + 1'b1, (est == 2'd2) ? n - 13'd1 : n, n);
                end
                // proxy (independent of the ring)
                dp = pval(pw, kind) - pval(p_ref_w, kind);
                if (dp > I32) dp = I32;
                if (dp < -I32) dp = -I32;
                uu = rhu(dp * g_u + u_off, sh_u);
                uc <= (uu > ONE) || (uu < -ONE);
                u <= (uu > ONE) ? ONE[31:0] : ((uu < -ONE) ? -ONE[31:0] : uu[31:0]);
                pr <= pval(prev_w, kind);
                prev_w <= pw;
                acc <= 64'sd0;
                j <= 13'd0;
            end
        end else begin
            case (ph)
                3'd0: begin                                 // ring read (the word n, or n-1 for lsq, back)
                    rd_w <= ring[rd_addr];
                    rd_addr <= (rd_addr == n) ? 0 : rd_addr + 1'b1;
                    ph <= 3'd1;
                end
                3'd1: begin
                    if (est == 2'd2) begin                  // lsq: one product per ring word
                        acc <= acc + ($signed({19'd0, j, 1'b0}) - $signed({51'd0, n}) + 64'sd1)
                                     * (pval(rd_w, kind) - p);
                        rd_w <= ring[rd_addr];
                        rd_addr <= (rd_addr == n) ? 0 : rd_addr + 1'b1;
                        j <= j + 1'b1;
                        if (j == n - 13'd1) ph <= 3'd2;
                    end else
                        ph <= 3'd2;
                end
                3'd2: begin
                    case (est)
                        2'd0, 2'd1: s <= (k >= {19'd0, n}) ? p - pval(rd_w, kind) : 64'sd0;
                        2'd2: s <= (k >= {19'd0, n} - 32'd1) ? acc : 64'sd0;
                        default: begin
                            if (k == 32'd1) begin
                                iy <= (p - pr) * 64'sd16777216;
                                s <= (p - pr) * 64'sd16777216;
                            end else if (k >= 32'd2) begin
                                iy <= iy + rhu((p - pr) * 64'sd16777216 - iy, {1'b0, ishift});
                                s <= iy + rhu((p - pr) * 64'sd16777216 - iy, {1'b0, ishift});
                            end else
                                s <= iy;
                        end
                    endcase
                    ph <= 3'd3;
                end
                default: begin
                    warm <= k < warmup;
                    if (k < warmup) begin
                        k <= k + 32'd1;
                        v <= 32'sd0;
                        vc <= 1'b0;
                    end else begin
                        sc = s;
                        sclamp = 1'b0;
                        if (sc > (64'sd1 <<< sb) - 64'sd1) begin sc = (64'sd1 <<< sb) - 64'sd1; sclamp = 1'b1; end
                        if (sc < 64'sd1 - (64'sd1 <<< sb)) begin sc = 64'sd1 - (64'sd1 <<< sb); sclamp = 1'b1; end
                        vv = rhu(sc * g_v, sh_v);
                        vc <= sclamp || (vv > ONE) || (vv < -ONE);
                        v <= (vv > ONE) ? ONE[31:0] : ((vv < -ONE) ? -ONE[31:0] : vv[31:0]);
                    end
                    busy <= 1'b0;
                    done <= 1'b1;
                end
            endcase
        end
    end
endmodule
