// Behavioural simulation model of the Lattice iCE40 DSP block SB_MAC16, for running ikseries'
// exported Verilog in Icarus Verilog and Verilator, in the configuration ikseries instantiates
// (ikseries.constraints.ice40.SB_MAC16_PARAMETERS): a signed 16 x 16 multiplier whose A and B
// inputs and 32-bit product are registered, every other configuration stopping the simulation
// instead of being modelled wrongly. Written from Lattice TN1295 (DSP function usage guide for
// iCE40 devices) and checked bit for bit against the SB_MAC16 of Yosys's ice40/cells_sim.v
// (tests/test_devices.py), the full model, which is not used here because it is not part of
// the Python package and sizes its internal partial products for every mode:
//
//   A_REG = B_REG = 1: A and B registered on the rising edge of CLK when CE is high
//                      (AHOLD = BHOLD = 0), cleared while IRSTTOP (A) / IRSTBOT (B) is high;
//   PIPELINE_16x16_MULT_REG2 = 1: the 32-bit product of the registered operands registered
//                      the same way (cleared by IRSTBOT);
//   TOPOUTPUT_SELECT = BOTOUTPUT_SELECT = 3: O = that register;
//   A_SIGNED = B_SIGNED = 1, MODE_8x8 = 0, NEG_TRIGGER = 0; C, D, the 8 x 8 product registers,
//   the adders and the accumulator outputs are unused (their inputs must be 0).
`default_nettype none

module SB_MAC16 (
    input wire CLK, CE,
    input wire [15:0] C, A, B, D,
    input wire AHOLD, BHOLD, CHOLD, DHOLD,
    input wire IRSTTOP, IRSTBOT,
    input wire ORSTTOP, ORSTBOT,
    input wire OLOADTOP, OLOADBOT,
    input wire ADDSUBTOP, ADDSUBBOT,
    input wire OHOLDTOP, OHOLDBOT,
    input wire CI, ACCUMCI, SIGNEXTIN,
    output wire [31:0] O,
    output wire CO, ACCUMCO, SIGNEXTOUT
);
    parameter [0:0] NEG_TRIGGER = 0;
    parameter [0:0] C_REG = 0;
    parameter [0:0] A_REG = 0;
    parameter [0:0] B_REG = 0;
    parameter [0:0] D_REG = 0;
    parameter [0:0] TOP_8x8_MULT_REG = 0;
    parameter [0:0] BOT_8x8_MULT_REG = 0;
    parameter [0:0] PIPELINE_16x16_MULT_REG1 = 0;
    parameter [0:0] PIPELINE_16x16_MULT_REG2 = 0;
    parameter [1:0] TOPOUTPUT_SELECT = 0;
    parameter [1:0] TOPADDSUB_LOWERINPUT = 0;
    parameter [0:0] TOPADDSUB_UPPERINPUT = 0;
    parameter [1:0] TOPADDSUB_CARRYSELECT = 0;
    parameter [1:0] BOTOUTPUT_SELECT = 0;
    parameter [1:0] BOTADDSUB_LOWERINPUT = 0;
    parameter [0:0] BOTADDSUB_UPPERINPUT = 0;
    parameter [1:0] BOTADDSUB_CARRYSELECT = 0;
    parameter [0:0] MODE_8x8 = 0;
    parameter [0:0] A_SIGNED = 0;
    parameter [0:0] B_SIGNED = 0;

    localparam SUPPORTED =
        NEG_TRIGGER == 0 && C_REG == 0 && A_REG == 1 && B_REG == 1 && D_REG == 0 &&
        TOP_8x8_MULT_REG == 0 && BOT_8x8_MULT_REG == 0 &&
        PIPELINE_16x16_MULT_REG1 == 0 && PIPELINE_16x16_MULT_REG2 == 1 &&
        TOPOUTPUT_SELECT == 3 && BOTOUTPUT_SELECT == 3 &&
        MODE_8x8 == 0 && A_SIGNED == 1 && B_SIGNED == 1;
    initial if (!SUPPORTED) begin
        $display("SB_MAC16 model (ikseries): configuration not modelled in %m");
        $finish;
    end
    // the unused inputs tied low, as ikseries ties them (anything else is not modelled)
    wire unused_high = |{C, D, AHOLD, BHOLD, CHOLD, DHOLD, ORSTTOP, ORSTBOT, OLOADTOP, OLOADBOT,
                         ADDSUBTOP, ADDSUBBOT, OHOLDTOP, OHOLDBOT, CI, ACCUMCI, SIGNEXTIN};
    always @(posedge CLK) if (unused_high !== 1'b0) begin
        $display("SB_MAC16 model (ikseries): C, D, the hold, load, add/sub, output reset and carry inputs must be 0 in %m");
        $finish;
    end

    reg [15:0] a_r = 16'd0, b_r = 16'd0;
    always @(posedge CLK, posedge IRSTTOP)
        if (IRSTTOP) a_r <= 16'd0;
        else if (CE) a_r <= A;
    always @(posedge CLK, posedge IRSTBOT)
        if (IRSTBOT) b_r <= 16'd0;
        else if (CE) b_r <= B;
    wire [31:0] ax = {{16{a_r[15]}}, a_r};
    wire [31:0] bx = {{16{b_r[15]}}, b_r};
    reg [31:0] h_r = 32'd0;
    always @(posedge CLK, posedge IRSTBOT)
        if (IRSTBOT) h_r <= 32'd0;
        else if (CE) h_r <= ax * bx;   // modulo 2**32: the exact signed product, which fits
    assign O = h_r;
    assign SIGNEXTOUT = a_r[15];   // the top adder's lower input, the registered A
    assign CO = 1'bx;              // the adders' carries are not modelled (nothing uses them)
    assign ACCUMCO = 1'bx;
endmodule

`default_nettype wire
