// Simulation models for the cells of the board-top netlist that yosys ships no model of
// (its share/ecp5/cells_sim.v has LUT4, CCU2C, TRELLIS_FF, PFUMX, L6MUX21, TRELLIS_IO and
// distributed RAM; DP16KD and ODDRX1F are black boxes there). Written by skinbox from
// Lattice's descriptions of the primitives (TN1264 "ECP5 and ECP5-5G Memory Usage Guide",
// TN1265 "ECP5 and ECP5-5G High-Speed I/O Interface") and the INITVAL layout yosys uses
// (checked by tests/synth_flow.rs, block_ram_contents_are_where_yosys_puts_them), for
// synth/src/netlist_sim.rs.

// The PLL bypassed: the harness drives the 125 MHz clock into CLKI; LOCK rises after 64
// clocks, as a PLL that needs time to lock.
module EHXPLLL (
    input CLKI, input CLKFB, input PHASESEL1, input PHASESEL0, input PHASEDIR,
    input PHASESTEP, input PHASELOADREG, input STDBY, input PLLWAKESYNC, input RST,
    input ENCLKOP, input ENCLKOS, input ENCLKOS2, input ENCLKOS3,
    output CLKOP, output CLKOS, output CLKOS2, output CLKOS3, output LOCK, output INTLOCK,
    output REFCLK, output CLKINTFB
);
    parameter CLKI_DIV = 1;
    parameter CLKFB_DIV = 1;
    parameter CLKOP_DIV = 8;
    parameter CLKOS_DIV = 8;
    parameter CLKOS2_DIV = 8;
    parameter CLKOS3_DIV = 8;
    parameter CLKOP_ENABLE = "ENABLED";
    parameter CLKOS_ENABLE = "DISABLED";
    parameter CLKOS2_ENABLE = "DISABLED";
    parameter CLKOS3_ENABLE = "DISABLED";
    parameter CLKOP_CPHASE = 0;
    parameter CLKOS_CPHASE = 0;
    parameter CLKOS2_CPHASE = 0;
    parameter CLKOS3_CPHASE = 0;
    parameter CLKOP_FPHASE = 0;
    parameter CLKOS_FPHASE = 0;
    parameter CLKOS2_FPHASE = 0;
    parameter CLKOS3_FPHASE = 0;
    parameter FEEDBK_PATH = "CLKOP";
    parameter CLKOP_TRIM_POL = "RISING";
    parameter CLKOP_TRIM_DELAY = 0;
    parameter CLKOS_TRIM_POL = "RISING";
    parameter CLKOS_TRIM_DELAY = 0;
    parameter OUTDIVIDER_MUXA = "DIVA";
    parameter OUTDIVIDER_MUXB = "DIVB";
    parameter OUTDIVIDER_MUXC = "DIVC";
    parameter OUTDIVIDER_MUXD = "DIVD";
    parameter PLL_LOCK_MODE = 0;
    parameter PLL_LOCK_DELAY = 200;
    parameter STDBY_ENABLE = "DISABLED";
    parameter REFIN_RESET = "DISABLED";
    parameter SYNC_ENABLE = "DISABLED";
    parameter INT_LOCK_STICKY = "ENABLED";
    parameter DPHASE_SOURCE = "DISABLED";
    parameter PLLRST_ENA = "DISABLED";
    parameter INTFB_WAKE = "DISABLED";
    reg [6:0] lock_count = 7'd0;
    always @(posedge CLKI) if (!lock_count[6]) lock_count <= lock_count + 7'd1;
    assign CLKOP = CLKI;
    assign CLKOS = 1'b0;
    assign CLKOS2 = 1'b0;
    assign CLKOS3 = 1'b0;
    assign LOCK = lock_count[6];
    assign INTLOCK = lock_count[6];
    assign REFCLK = CLKI;
    assign CLKINTFB = 1'b0;
endmodule

// DDR output: D0 and D1 are registered at the rising edge of SCLK; Q carries D0 while SCLK
// is high and D1 (moved into a falling-edge register) while it is low, one clock after they
// were presented.
module ODDRX1F (input SCLK, input RST, input D0, input D1, output Q);
    parameter GSR = "ENABLED";
    reg rise_data = 1'b0;
    reg fall_data = 1'b0;
    reg fall_out = 1'b0;
    always @(posedge SCLK) begin
        rise_data <= RST ? 1'b0 : D0;
        fall_data <= RST ? 1'b0 : D1;
    end
    always @(negedge SCLK) fall_out <= fall_data;
    assign Q = SCLK ? rise_data : fall_out;
endmodule

// DDR input: D sampled at the rising edge (Q0) and at the falling edge (Q1) of SCLK, both
// presented at the next rising edge (TN1265, the IDDRX1F timing diagram). The netlist
// simulation drives no receive clock; the model is here so the board top elaborates.
module IDDRX1F (input SCLK, input RST, input D, output reg Q0, output reg Q1);
    parameter GSR = "ENABLED";
    reg rise_data = 1'b0;
    reg fall_data = 1'b0;
    initial begin
        Q0 = 1'b0;
        Q1 = 1'b0;
    end
    always @(posedge SCLK) rise_data <= RST ? 1'b0 : D;
    always @(negedge SCLK) fall_data <= RST ? 1'b0 : D;
    always @(posedge SCLK) begin
        Q0 <= RST ? 1'b0 : rise_data;
        Q1 <= RST ? 1'b0 : fall_data;
    end
endmodule

// Input delay element: no delay in a cycle-based simulation.
module DELAYG (input A, output Z);
    parameter DEL_MODE = "USER_DEFINED";
    parameter DEL_VALUE = 0;
    assign Z = A;
endmodule

// 18 kbit true dual-port block RAM in the modes the box uses: 1024 x 18 (address bits
// 13:4, byte enables on address bits 1:0 for writes), 2048 x 9 (address bits 13:3) and,
// for RAMs that start empty, 4096 x 4 (address bits 13:2; its packing into the rows is
// this model's own, so initial contents in that mode stop the simulation).
// The array is 1024 rows of 18 bits; INITVAL_xx holds rows 16 xx to 16 xx + 15, each in 20
// bits (18 data, 2 unused). A 9-bit word a is bits 9 (a % 2) of row a / 2. Reads are
// synchronous (the array's output register at the clock edge) and, with REGMODE "OUTREG",
// pass through the output register one clock later. Chip selects must match CSDECODE.
// WRITEMODE "NORMAL": a write leaves the port's output unchanged. Other modes stop the
// simulation.
module DP16KD (
    input DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0,
    input ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0,
    input CEA, OCEA, CLKA, WEA, RSTA,
    input CSA2, CSA1, CSA0,
    output DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0,
    input DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0,
    input ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0,
    input CEB, OCEB, CLKB, WEB, RSTB,
    input CSB2, CSB1, CSB0,
    output DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0
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
    parameter WID = 0;
    parameter CLKAMUX = "CLKA";
    parameter CLKBMUX = "CLKB";
    parameter [319:0] INITVAL_00 = 320'h0, INITVAL_01 = 320'h0, INITVAL_02 = 320'h0, INITVAL_03 = 320'h0;
    parameter [319:0] INITVAL_04 = 320'h0, INITVAL_05 = 320'h0, INITVAL_06 = 320'h0, INITVAL_07 = 320'h0;
    parameter [319:0] INITVAL_08 = 320'h0, INITVAL_09 = 320'h0, INITVAL_0A = 320'h0, INITVAL_0B = 320'h0;
    parameter [319:0] INITVAL_0C = 320'h0, INITVAL_0D = 320'h0, INITVAL_0E = 320'h0, INITVAL_0F = 320'h0;
    parameter [319:0] INITVAL_10 = 320'h0, INITVAL_11 = 320'h0, INITVAL_12 = 320'h0, INITVAL_13 = 320'h0;
    parameter [319:0] INITVAL_14 = 320'h0, INITVAL_15 = 320'h0, INITVAL_16 = 320'h0, INITVAL_17 = 320'h0;
    parameter [319:0] INITVAL_18 = 320'h0, INITVAL_19 = 320'h0, INITVAL_1A = 320'h0, INITVAL_1B = 320'h0;
    parameter [319:0] INITVAL_1C = 320'h0, INITVAL_1D = 320'h0, INITVAL_1E = 320'h0, INITVAL_1F = 320'h0;
    parameter [319:0] INITVAL_20 = 320'h0, INITVAL_21 = 320'h0, INITVAL_22 = 320'h0, INITVAL_23 = 320'h0;
    parameter [319:0] INITVAL_24 = 320'h0, INITVAL_25 = 320'h0, INITVAL_26 = 320'h0, INITVAL_27 = 320'h0;
    parameter [319:0] INITVAL_28 = 320'h0, INITVAL_29 = 320'h0, INITVAL_2A = 320'h0, INITVAL_2B = 320'h0;
    parameter [319:0] INITVAL_2C = 320'h0, INITVAL_2D = 320'h0, INITVAL_2E = 320'h0, INITVAL_2F = 320'h0;
    parameter [319:0] INITVAL_30 = 320'h0, INITVAL_31 = 320'h0, INITVAL_32 = 320'h0, INITVAL_33 = 320'h0;
    parameter [319:0] INITVAL_34 = 320'h0, INITVAL_35 = 320'h0, INITVAL_36 = 320'h0, INITVAL_37 = 320'h0;
    parameter [319:0] INITVAL_38 = 320'h0, INITVAL_39 = 320'h0, INITVAL_3A = 320'h0, INITVAL_3B = 320'h0;
    parameter [319:0] INITVAL_3C = 320'h0, INITVAL_3D = 320'h0, INITVAL_3E = 320'h0, INITVAL_3F = 320'h0;

    localparam [64*320-1:0] INIT = {
        INITVAL_3F, INITVAL_3E, INITVAL_3D, INITVAL_3C, INITVAL_3B, INITVAL_3A, INITVAL_39, INITVAL_38,
        INITVAL_37, INITVAL_36, INITVAL_35, INITVAL_34, INITVAL_33, INITVAL_32, INITVAL_31, INITVAL_30,
        INITVAL_2F, INITVAL_2E, INITVAL_2D, INITVAL_2C, INITVAL_2B, INITVAL_2A, INITVAL_29, INITVAL_28,
        INITVAL_27, INITVAL_26, INITVAL_25, INITVAL_24, INITVAL_23, INITVAL_22, INITVAL_21, INITVAL_20,
        INITVAL_1F, INITVAL_1E, INITVAL_1D, INITVAL_1C, INITVAL_1B, INITVAL_1A, INITVAL_19, INITVAL_18,
        INITVAL_17, INITVAL_16, INITVAL_15, INITVAL_14, INITVAL_13, INITVAL_12, INITVAL_11, INITVAL_10,
        INITVAL_0F, INITVAL_0E, INITVAL_0D, INITVAL_0C, INITVAL_0B, INITVAL_0A, INITVAL_09, INITVAL_08,
        INITVAL_07, INITVAL_06, INITVAL_05, INITVAL_04, INITVAL_03, INITVAL_02, INITVAL_01, INITVAL_00};

    reg [17:0] rows [0:1023];
    integer r;
    initial begin
        if ((DATA_WIDTH_A != 18 && DATA_WIDTH_A != 9 && DATA_WIDTH_A != 4)
            || (DATA_WIDTH_B != 18 && DATA_WIDTH_B != 9 && DATA_WIDTH_B != 4)
            || ((DATA_WIDTH_A == 4 || DATA_WIDTH_B == 4) && INIT != 0)
            || (WRITEMODE_A != "NORMAL") || (WRITEMODE_B != "NORMAL")) begin
            $display("DP16KD model: mode not modelled (widths %0d/%0d)", DATA_WIDTH_A, DATA_WIDTH_B);
            $finish;
        end
        for (r = 0; r < 1024; r = r + 1)
            rows[r] = INIT[r * 20 +: 18];
    end

    wire [17:0] dia = {DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0};
    wire [17:0] dib = {DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0};
    wire [13:0] ada = {ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0};
    wire [13:0] adb = {ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0};

    // CSDECODE is a string "0bXYZ": its last three characters, '0' or '1'.
    function [2:0] decode(input [8*5-1:0] text);
        decode = {text[16], text[8], text[0]};
    endfunction

    reg [17:0] array_a = 18'd0, array_b = 18'd0, out_a = 18'd0, out_b = 18'd0;

    function [17:0] read_word(input integer width, input [13:0] address);
        reg [17:0] row;
        begin
            if (width == 18) begin
                read_word = rows[address[13:4]];
            end else if (width == 4) begin
                row = rows[address[13:4]];
                read_word = {14'd0, row[address[3:2] * 4 +: 4]};
            end else begin
                row = rows[address[13:4]];
                read_word = address[3] ? {9'd0, row[17:9]} : {9'd0, row[8:0]};
            end
        end
    endfunction

    always @(posedge CLKA) begin
        if (CEA && {CSA2, CSA1, CSA0} == decode(CSDECODE_A)) begin
            if (WEA) begin
                if (DATA_WIDTH_A == 18) begin
                    if (ada[0]) rows[ada[13:4]][8:0] <= dia[8:0];
                    if (ada[1]) rows[ada[13:4]][17:9] <= dia[17:9];
                end else if (DATA_WIDTH_A == 4) rows[ada[13:4]][ada[3:2] * 4 +: 4] <= dia[3:0];
                else if (ada[3]) rows[ada[13:4]][17:9] <= dia[8:0];
                else rows[ada[13:4]][8:0] <= dia[8:0];
            end else begin
                array_a <= read_word(DATA_WIDTH_A, ada);
            end
        end
        if (OCEA) out_a <= array_a;
    end
    always @(posedge CLKB) begin
        if (CEB && {CSB2, CSB1, CSB0} == decode(CSDECODE_B)) begin
            if (WEB) begin
                if (DATA_WIDTH_B == 18) begin
                    if (adb[0]) rows[adb[13:4]][8:0] <= dib[8:0];
                    if (adb[1]) rows[adb[13:4]][17:9] <= dib[17:9];
                end else if (DATA_WIDTH_B == 4) rows[adb[13:4]][adb[3:2] * 4 +: 4] <= dib[3:0];
                else if (adb[3]) rows[adb[13:4]][17:9] <= dib[8:0];
                else rows[adb[13:4]][8:0] <= dib[8:0];
            end else begin
                array_b <= read_word(DATA_WIDTH_B, adb);
            end
        end
        if (OCEB) out_b <= array_b;
    end
    wire [17:0] doa = REGMODE_A == "OUTREG" ? out_a : array_a;
    wire [17:0] dob = REGMODE_B == "OUTREG" ? out_b : array_b;
    assign {DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0} = doa;
    assign {DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0} = dob;
endmodule

// yosys' tristate buffer (its simcells.v has the same): MDIO's output enable.
module \$_TBUF_ (input A, input E, output Y);
    assign Y = E ? A : 1'bz;
endmodule
