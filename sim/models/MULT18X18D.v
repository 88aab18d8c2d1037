// Behavioural simulation model of the Lattice ECP5 sysDSP multiplier MULT18X18D, for running
// ikseries' exported Verilog in Icarus Verilog and Verilator (Yosys ships the primitive only as
// a black box, and Lattice's own library is not installable here). Written from the primitive's
// documented behaviour (Lattice TN1267, ECP5 sysDSP usage guide), for the configuration
// ikseries instantiates; any other configuration stops the simulation instead of being
// modelled wrongly:
//
//   P = A * B (36 bits), each operand sign-extended when its SIGNEDx pin is high;
//   REG_INPUTA_CLK, REG_INPUTB_CLK, REG_PIPELINE_CLK, REG_OUTPUT_CLK: "NONE" (bypassed) or
//   "CLK0" (a register on the rising edge of CLK0, enabled by CE0, synchronously cleared by
//   RST0; the operand registers also register SIGNEDA / SIGNEDB);
//   *_CE = "CE0", *_RST = "RST0", RESETMODE = "SYNC", REG_INPUTC_CLK = "NONE",
//   CLK0_DIV = "ENABLED" (the default), SOURCEA = SOURCEB = 0 (no shift chains); C is unused.
`default_nettype none

module MULT18X18D #(
    parameter REG_INPUTA_CLK = "NONE", parameter REG_INPUTA_CE = "CE0", parameter REG_INPUTA_RST = "RST0",
    parameter REG_INPUTB_CLK = "NONE", parameter REG_INPUTB_CE = "CE0", parameter REG_INPUTB_RST = "RST0",
    parameter REG_INPUTC_CLK = "NONE", parameter REG_INPUTC_CE = "CE0", parameter REG_INPUTC_RST = "RST0",
    parameter REG_PIPELINE_CLK = "NONE", parameter REG_PIPELINE_CE = "CE0", parameter REG_PIPELINE_RST = "RST0",
    parameter REG_OUTPUT_CLK = "NONE", parameter REG_OUTPUT_CE = "CE0", parameter REG_OUTPUT_RST = "RST0",
    parameter CLK0_DIV = "ENABLED", parameter CLK1_DIV = "ENABLED", parameter CLK2_DIV = "ENABLED",
    parameter CLK3_DIV = "ENABLED", parameter HIGHSPEED_CLK = "NONE", parameter GSR = "ENABLED",
    parameter CAS_MATCH_REG = "FALSE", parameter SOURCEB_MODE = "B_SHIFT", parameter MULT_BYPASS = "DISABLED",
    parameter RESETMODE = "SYNC"
) (
    input wire A0, A1, A2, A3, A4, A5, A6, A7, A8, A9, A10, A11, A12, A13, A14, A15, A16, A17,
    input wire B0, B1, B2, B3, B4, B5, B6, B7, B8, B9, B10, B11, B12, B13, B14, B15, B16, B17,
    input wire C0, C1, C2, C3, C4, C5, C6, C7, C8, C9, C10, C11, C12, C13, C14, C15, C16, C17,
    input wire SIGNEDA, SIGNEDB, SOURCEA, SOURCEB,
    input wire CLK0, CLK1, CLK2, CLK3, CE0, CE1, CE2, CE3, RST0, RST1, RST2, RST3,
    output wire P0, P1, P2, P3, P4, P5, P6, P7, P8, P9, P10, P11, P12, P13, P14, P15, P16, P17, P18, P19, P20, P21, P22, P23, P24, P25, P26, P27, P28, P29, P30, P31, P32, P33, P34, P35
);
    localparam SUPPORTED =
        (REG_INPUTA_CLK == "NONE" || REG_INPUTA_CLK == "CLK0") && REG_INPUTA_CE == "CE0" && REG_INPUTA_RST == "RST0" &&
        (REG_INPUTB_CLK == "NONE" || REG_INPUTB_CLK == "CLK0") && REG_INPUTB_CE == "CE0" && REG_INPUTB_RST == "RST0" &&
        (REG_PIPELINE_CLK == "NONE" || REG_PIPELINE_CLK == "CLK0") && REG_PIPELINE_CE == "CE0" &&
        REG_PIPELINE_RST == "RST0" &&
        (REG_OUTPUT_CLK == "NONE" || REG_OUTPUT_CLK == "CLK0") && REG_OUTPUT_CE == "CE0" && REG_OUTPUT_RST == "RST0" &&
        REG_INPUTC_CLK == "NONE" && CLK0_DIV == "ENABLED" && HIGHSPEED_CLK == "NONE" && CAS_MATCH_REG == "FALSE" &&
        MULT_BYPASS == "DISABLED" && RESETMODE == "SYNC";
    initial if (!SUPPORTED) begin
        $display("MULT18X18D model (ikseries): configuration not modelled in %m");
        $finish;
    end
    always @(posedge CLK0) if (SOURCEA !== 1'b0 || SOURCEB !== 1'b0) begin
        $display("MULT18X18D model (ikseries): SOURCEA/SOURCEB shift chains are not modelled in %m");
        $finish;
    end

    wire [17:0] a_in = {A17, A16, A15, A14, A13, A12, A11, A10, A9, A8, A7, A6, A5, A4, A3, A2, A1, A0};
    wire [17:0] b_in = {B17, B16, B15, B14, B13, B12, B11, B10, B9, B8, B7, B6, B5, B4, B3, B2, B1, B0};
    reg [17:0] a_r = 18'd0, b_r = 18'd0;
    reg sa_r = 1'b0, sb_r = 1'b0;
    always @(posedge CLK0)
        if (RST0) begin
            a_r <= 18'd0; sa_r <= 1'b0; b_r <= 18'd0; sb_r <= 1'b0;
        end else if (CE0) begin
            a_r <= a_in; sa_r <= SIGNEDA; b_r <= b_in; sb_r <= SIGNEDB;
        end
    wire [17:0] a = REG_INPUTA_CLK == "NONE" ? a_in : a_r;
    wire [17:0] b = REG_INPUTB_CLK == "NONE" ? b_in : b_r;
    wire sa = REG_INPUTA_CLK == "NONE" ? SIGNEDA : sa_r;
    wire sb = REG_INPUTB_CLK == "NONE" ? SIGNEDB : sb_r;
    wire [35:0] ax = {{18{sa & a[17]}}, a};
    wire [35:0] bx = {{18{sb & b[17]}}, b};
    wire [35:0] product = ax * bx;      // modulo 2**36: the exact product, which fits 36 bits

    reg [35:0] pipe_r = 36'd0, out_r = 36'd0;
    wire [35:0] piped = REG_PIPELINE_CLK == "NONE" ? product : pipe_r;
    always @(posedge CLK0)
        if (RST0) begin
            pipe_r <= 36'd0; out_r <= 36'd0;
        end else if (CE0) begin
            pipe_r <= product; out_r <= piped;
        end
    wire [35:0] p = REG_OUTPUT_CLK == "NONE" ? piped : out_r;
    assign P0 = p[0];
    assign P1 = p[1];
    assign P2 = p[2];
    assign P3 = p[3];
    assign P4 = p[4];
    assign P5 = p[5];
    assign P6 = p[6];
    assign P7 = p[7];
    assign P8 = p[8];
    assign P9 = p[9];
    assign P10 = p[10];
    assign P11 = p[11];
    assign P12 = p[12];
    assign P13 = p[13];
    assign P14 = p[14];
    assign P15 = p[15];
    assign P16 = p[16];
    assign P17 = p[17];
    assign P18 = p[18];
    assign P19 = p[19];
    assign P20 = p[20];
    assign P21 = p[21];
    assign P22 = p[22];
    assign P23 = p[23];
    assign P24 = p[24];
    assign P25 = p[25];
    assign P26 = p[26];
    assign P27 = p[27];
    assign P28 = p[28];
    assign P29 = p[29];
    assign P30 = p[30];
    assign P31 = p[31];
    assign P32 = p[32];
    assign P33 = p[33];
    assign P34 = p[34];
    assign P35 = p[35];
endmodule

`default_nettype wire
