// Behavioural simulation model of the Lattice ECP5 embedded block RAM DP16KD, for running
// ikseries' exported Verilog in Icarus Verilog and Verilator (Yosys ships the primitive only as
// a black box, and Lattice's own library is not installable here). Written from the primitive's
// documented behaviour (Lattice TN1264, ECP5 memory usage guide) for the configuration ikseries
// instantiates (ikseries.constraints.ecp5.dp16kd_rom: a ROM on port A); any other configuration
// stops the simulation instead of being modelled wrongly:
//
//   DATA_WIDTH_A = 1, 2, 4, 9 or 18 (16384 x 1 ... 1024 x 18); the address is ADA13 down to
//   ADA0, ADA1, ADA2, ADA3 or ADA4 (the lower pins unused or byte enables); data DOA0 up;
//   at a rising edge of CLKA with CEA high the word at the address goes to the data latch
//   (CSA = 0 with CSDECODE_A = "0b000": the block is selected; WEA = 0: never written);
//   REGMODE_A = "NOREG": DOA = the latch, cleared at an edge with RSTA high;
//   REGMODE_A = "OUTREG": DOA = the output register, which takes the latch at an edge with OCEA
//   high and is cleared at an edge with RSTA high (RESETMODE = "SYNC"; reset wins over OCEA);
//   the latch is not cleared (ikseries reads no table word before a read enabled after reset);
//   port B unused (CEB = WEB = 0). Registers start at 0 (the configured device's state).
//
// Contents: INITVAL_00 .. INITVAL_3F read as one 20480-bit number (INITVAL_00 the low bits)
// are 1024 slots of 20 bits, each two 9-bit bytes (bits 0-8, 9-17) and 2 unused bits; 9- and
// 18-bit words fill whole bytes, 1-, 2- and 4-bit words the low 8 bits of each byte, the low
// address first (ikseries.constraints.ecp5.dp16kd_bit; the layout Yosys's ECP5 memory mapping
// writes, tests/test_ebr.py).
`default_nettype none

module DP16KD (
    input wire DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0,
    input wire ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0,
    input wire CEA, OCEA, CLKA, WEA, RSTA,
    input wire CSA2, CSA1, CSA0,
    output wire DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0,
    input wire DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0,
    input wire ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0,
    input wire CEB, OCEB, CLKB, WEB, RSTB,
    input wire CSB2, CSB1, CSB0,
    output wire DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0
);
    parameter DATA_WIDTH_A = 18;
    parameter DATA_WIDTH_B = 18;
    parameter REGMODE_A = "NOREG";
    parameter REGMODE_B = "NOREG";
    parameter RESETMODE = "SYNC";
    parameter ASYNC_RESET_RELEASE = "SYNC";
    parameter CSDECODE_A = "0b000";
    parameter CSDECODE_B = "0b000";
    parameter WRITEMODE_A = "NORMAL";
    parameter WRITEMODE_B = "NORMAL";
    parameter GSR = "ENABLED";
    parameter INIT_DATA = "STATIC";
    parameter [319:0] INITVAL_00 = 320'h0;
    parameter [319:0] INITVAL_01 = 320'h0;
    parameter [319:0] INITVAL_02 = 320'h0;
    parameter [319:0] INITVAL_03 = 320'h0;
    parameter [319:0] INITVAL_04 = 320'h0;
    parameter [319:0] INITVAL_05 = 320'h0;
    parameter [319:0] INITVAL_06 = 320'h0;
    parameter [319:0] INITVAL_07 = 320'h0;
    parameter [319:0] INITVAL_08 = 320'h0;
    parameter [319:0] INITVAL_09 = 320'h0;
    parameter [319:0] INITVAL_0A = 320'h0;
    parameter [319:0] INITVAL_0B = 320'h0;
    parameter [319:0] INITVAL_0C = 320'h0;
    parameter [319:0] INITVAL_0D = 320'h0;
    parameter [319:0] INITVAL_0E = 320'h0;
    parameter [319:0] INITVAL_0F = 320'h0;
    parameter [319:0] INITVAL_10 = 320'h0;
    parameter [319:0] INITVAL_11 = 320'h0;
    parameter [319:0] INITVAL_12 = 320'h0;
    parameter [319:0] INITVAL_13 = 320'h0;
    parameter [319:0] INITVAL_14 = 320'h0;
    parameter [319:0] INITVAL_15 = 320'h0;
    parameter [319:0] INITVAL_16 = 320'h0;
    parameter [319:0] INITVAL_17 = 320'h0;
    parameter [319:0] INITVAL_18 = 320'h0;
    parameter [319:0] INITVAL_19 = 320'h0;
    parameter [319:0] INITVAL_1A = 320'h0;
    parameter [319:0] INITVAL_1B = 320'h0;
    parameter [319:0] INITVAL_1C = 320'h0;
    parameter [319:0] INITVAL_1D = 320'h0;
    parameter [319:0] INITVAL_1E = 320'h0;
    parameter [319:0] INITVAL_1F = 320'h0;
    parameter [319:0] INITVAL_20 = 320'h0;
    parameter [319:0] INITVAL_21 = 320'h0;
    parameter [319:0] INITVAL_22 = 320'h0;
    parameter [319:0] INITVAL_23 = 320'h0;
    parameter [319:0] INITVAL_24 = 320'h0;
    parameter [319:0] INITVAL_25 = 320'h0;
    parameter [319:0] INITVAL_26 = 320'h0;
    parameter [319:0] INITVAL_27 = 320'h0;
    parameter [319:0] INITVAL_28 = 320'h0;
    parameter [319:0] INITVAL_29 = 320'h0;
    parameter [319:0] INITVAL_2A = 320'h0;
    parameter [319:0] INITVAL_2B = 320'h0;
    parameter [319:0] INITVAL_2C = 320'h0;
    parameter [319:0] INITVAL_2D = 320'h0;
    parameter [319:0] INITVAL_2E = 320'h0;
    parameter [319:0] INITVAL_2F = 320'h0;
    parameter [319:0] INITVAL_30 = 320'h0;
    parameter [319:0] INITVAL_31 = 320'h0;
    parameter [319:0] INITVAL_32 = 320'h0;
    parameter [319:0] INITVAL_33 = 320'h0;
    parameter [319:0] INITVAL_34 = 320'h0;
    parameter [319:0] INITVAL_35 = 320'h0;
    parameter [319:0] INITVAL_36 = 320'h0;
    parameter [319:0] INITVAL_37 = 320'h0;
    parameter [319:0] INITVAL_38 = 320'h0;
    parameter [319:0] INITVAL_39 = 320'h0;
    parameter [319:0] INITVAL_3A = 320'h0;
    parameter [319:0] INITVAL_3B = 320'h0;
    parameter [319:0] INITVAL_3C = 320'h0;
    parameter [319:0] INITVAL_3D = 320'h0;
    parameter [319:0] INITVAL_3E = 320'h0;
    parameter [319:0] INITVAL_3F = 320'h0;

    localparam integer W = DATA_WIDTH_A;
    localparam integer LSB = W == 18 ? 4 : W == 9 ? 3 : W == 4 ? 2 : W == 2 ? 1 : 0;
    localparam integer DEPTH = 16384 >> LSB;
    localparam integer PER_BYTE = W >= 9 ? 9 : 8;     // data bits of each 9-bit byte
    localparam SUPPORTED = (W == 1 || W == 2 || W == 4 || W == 9 || W == 18) &&
        (REGMODE_A == "NOREG" || REGMODE_A == "OUTREG") && RESETMODE == "SYNC" && CSDECODE_A == "0b000" &&
        INIT_DATA == "STATIC";
    initial if (!SUPPORTED) begin
        $display("DP16KD model (ikseries): configuration not modelled in %m");
        $finish;
    end

    wire [20479:0] contents = {
        INITVAL_3F, INITVAL_3E, INITVAL_3D, INITVAL_3C, INITVAL_3B, INITVAL_3A, INITVAL_39, INITVAL_38,
        INITVAL_37, INITVAL_36, INITVAL_35, INITVAL_34, INITVAL_33, INITVAL_32, INITVAL_31, INITVAL_30,
        INITVAL_2F, INITVAL_2E, INITVAL_2D, INITVAL_2C, INITVAL_2B, INITVAL_2A, INITVAL_29, INITVAL_28,
        INITVAL_27, INITVAL_26, INITVAL_25, INITVAL_24, INITVAL_23, INITVAL_22, INITVAL_21, INITVAL_20,
        INITVAL_1F, INITVAL_1E, INITVAL_1D, INITVAL_1C, INITVAL_1B, INITVAL_1A, INITVAL_19, INITVAL_18,
        INITVAL_17, INITVAL_16, INITVAL_15, INITVAL_14, INITVAL_13, INITVAL_12, INITVAL_11, INITVAL_10,
        INITVAL_0F, INITVAL_0E, INITVAL_0D, INITVAL_0C, INITVAL_0B, INITVAL_0A, INITVAL_09, INITVAL_08,
        INITVAL_07, INITVAL_06, INITVAL_05, INITVAL_04, INITVAL_03, INITVAL_02, INITVAL_01, INITVAL_00
    };
    reg [17:0] words [0:16383];
    integer a, b, q;
    initial
        for (a = 0; a < DEPTH; a = a + 1) begin
            words[a] = 18'd0;
            for (b = 0; b < W; b = b + 1) begin
                q = a * W + b;
                words[a][b] = contents[(q / PER_BYTE / 2) * 20 + ((q / PER_BYTE) % 2) * 9 + q % PER_BYTE];
            end
        end

    wire [13:0] ada = {ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0};
    wire [13:0] address = ada >> LSB;
    reg [17:0] latch = 18'd0, out_r = 18'd0;
    always @(posedge CLKA) begin
        if (WEA !== 1'b0 || {CSA2, CSA1, CSA0} !== 3'b000 || CEB !== 1'b0 || WEB !== 1'b0) begin
            $display("DP16KD model (ikseries): writes, chip selects and port B are not modelled in %m");
            $finish;
        end
        if (RSTA && REGMODE_A == "NOREG") latch <= 18'd0;
        else if (CEA) latch <= words[address];
        if (RSTA) out_r <= 18'd0;
        else if (OCEA) out_r <= latch;
    end
    wire [17:0] doa = REGMODE_A == "OUTREG" ? out_r : latch;
    assign {DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0} = doa;
    assign {DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0} = 18'd0;
endmodule

`default_nettype wire
