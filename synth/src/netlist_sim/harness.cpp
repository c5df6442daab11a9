// Clock loop around the verilated board-top netlist (synth/src/netlist_sim.rs writes the
// wrapper `sim_top` and reads what this prints).
//
// argv: STIMULUS OUTPUT. STIMULUS holds "reset_cycles R", "cycles C", then one line per
// UART pin change, "EDGE PORT LEVEL", in edge order, with the edges of the RTL
// co-simulation: its box leaves reset at edge R + 1. Here the box leaves reset one edge
// after eth_rst_n rises, so every edge is moved by (that edge - R).
//
// Out, one line each: "release K" (the edge after which eth_rst_n rose), "led K L" (every
// change of led_n), "frame K HEX" (a frame as an RGMII receiver sees it: K the edge whose
// rising half carried its first byte), "tx_er K" (a byte with TX_CTL's halves differing),
// "mdio write PHY REG VALUE K", "mdio read PHY REG K", "mdc_period MIN MAX", "end K".
#include "Vsim_top.h"
#include "verilated.h"
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

// A clause 22 PHY on the wire: samples MDIO at each rising MDC edge, answers reads of its
// address with the turnaround's 0 and 16 data bits, each driven after a rising edge.
struct Phy {
    unsigned address = 0;
    uint16_t regs[32] = {};
    unsigned ones = 0;
    bool in_frame = false;
    std::vector<int> bits;
    uint16_t answer = 0;
    bool drive = false;
    bool level = true;

    void rising(bool line, uint64_t edge, FILE *out) {
        if (!in_frame) {
            if (line) {
                ones++;
            } else {
                if (ones >= 32) {
                    in_frame = true;
                    bits.assign(1, 0);
                }
                ones = 0;
            }
            return;
        }
        bits.push_back(line ? 1 : 0);
        size_t n = bits.size();
        auto field = [&](size_t from, size_t to) {
            unsigned v = 0;
            for (size_t i = from; i < to; i++) v = (v << 1) | bits[i];
            return v;
        };
        bool read = n >= 4 && bits[2] == 1 && bits[3] == 0;
        unsigned phy = n >= 9 ? field(4, 9) : 0;
        if (n == 14 && read) {
            unsigned reg = field(9, 14);
            fprintf(out, "mdio read %u %u %llu\n", phy, reg, (unsigned long long)edge);
            answer = regs[reg];
        }
        if (read && phy == address) {
            if (n == 15) {
                drive = true;
                level = false;
            } else if (n >= 16 && n <= 31) {
                drive = true;
                level = (answer >> (31 - n)) & 1;
            } else {
                drive = false;
            }
        }
        if (n == 32) {
            if (!read) {
                unsigned reg = field(9, 14);
                unsigned value = field(16, 32);
                if (field(0, 2) == 1 && field(14, 16) == 2) {
                    fprintf(out, "mdio write %u %u %u %llu\n", phy, reg, value,
                            (unsigned long long)edge);
                    if (phy == address) regs[reg] = value;
                } else {
                    fprintf(out, "mdio malformed %llu\n", (unsigned long long)edge);
                }
            }
            in_frame = false;
            drive = false;
        }
    }
};

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s STIMULUS OUTPUT\n", argv[0]);
        return 2;
    }
    FILE *stim = fopen(argv[1], "r");
    FILE *out = fopen(argv[2], "w");
    if (!stim || !out) {
        fprintf(stderr, "cannot open %s or %s\n", argv[1], argv[2]);
        return 2;
    }
    unsigned long long reset_cycles = 0, cycles = 0;
    if (fscanf(stim, " reset_cycles %llu cycles %llu", &reset_cycles, &cycles) != 2) {
        fprintf(stderr, "%s: no header\n", argv[1]);
        return 2;
    }
    struct Change {
        uint64_t edge;
        unsigned port;
        int level;
    };
    std::vector<Change> changes;
    unsigned long long e;
    unsigned p;
    int l;
    while (fscanf(stim, " %llu %u %d", &e, &p, &l) == 3) changes.push_back({e, p, l});
    fclose(stim);

    Verilated::commandArgs(argc, argv);
    Vsim_top *top = new Vsim_top;
    Phy phy;
    phy.regs[1] = 0x796D;          // link up (bit 2), auto-negotiation complete
    phy.regs[0x19] = 0x0700 | 0x4; // 1000BASE-T full duplex negotiated, link up
    uint64_t pins = ~0ull;         // UART lines idle high
    top->uart_rx = pins;
    top->phy_drive = 0;
    top->phy_level = 1;
    top->clk = 0;
    top->eval();

    const uint64_t release_limit = 1ull << 23;
    uint64_t edge = 0, release = 0, end = 0;
    bool released = false;
    size_t next = 0;
    int led = top->led_n;
    fprintf(out, "led 0 %d\n", led);
    // RGMII receiver state
    int tx_clk = top->eth_tx_clk;
    unsigned low = 0, en = 0;
    bool have_low = false;
    std::string frame;
    uint64_t frame_edge = 0;
    bool in_frame = false;
    // MDC
    int mdc = top->eth_mdc;
    uint64_t last_mdc_rise = 0, mdc_min = ~0ull, mdc_max = 0;
    char hex[3];

    auto observe = [&]() {
        // the receiver keys off the forwarded clock pin: its rising half carries the low
        // nibble and TX_EN, its falling half the high nibble and TX_EN ^ TX_ER
        int clk_now = top->eth_tx_clk;
        if (clk_now && !tx_clk) {
            low = top->eth_tx_data & 0xF;
            en = top->eth_tx_ctl;
            have_low = true;
        } else if (!clk_now && tx_clk && have_low) {
            unsigned byte = low | ((top->eth_tx_data & 0xF) << 4);
            unsigned er = en ^ top->eth_tx_ctl;
            have_low = false;
            if (er) fprintf(out, "tx_er %llu\n", (unsigned long long)edge);
            if (en) {
                if (!in_frame) {
                    in_frame = true;
                    frame.clear();
                    frame_edge = edge;
                }
                snprintf(hex, sizeof hex, "%02x", byte);
                frame += hex;
            } else if (in_frame) {
                fprintf(out, "frame %llu %s\n", (unsigned long long)frame_edge, frame.c_str());
                in_frame = false;
            }
        }
        tx_clk = clk_now;
        if (top->led_n != led) {
            led = top->led_n;
            fprintf(out, "led %llu %d\n", (unsigned long long)edge, led);
        }
        int mdc_now = top->eth_mdc;
        if (mdc_now && !mdc) {
            if (last_mdc_rise) {
                uint64_t period = edge - last_mdc_rise;
                if (period < mdc_min) mdc_min = period;
                if (period > mdc_max) mdc_max = period;
            }
            last_mdc_rise = edge;
            phy.rising(top->mdio_line, edge, out);
            top->phy_drive = phy.drive;
            top->phy_level = phy.level;
        }
        mdc = mdc_now;
    };

    while (true) {
        // pin changes due before this edge
        if (released) {
            while (next < changes.size() && changes[next].edge + release - reset_cycles <= edge + 1) {
                if (changes[next].level)
                    pins |= 1ull << changes[next].port;
                else
                    pins &= ~(1ull << changes[next].port);
                next++;
            }
            top->uart_rx = pins;
        }
        top->clk = 1;
        top->eval();
        edge++;
        observe();
        top->clk = 0;
        top->eval();
        observe();
        if (!released && top->eth_rst_n) {
            released = true;
            release = edge;
            end = release - reset_cycles + cycles + 8;
            fprintf(out, "release %llu\n", (unsigned long long)release);
        }
        if (!released && edge > release_limit) {
            fprintf(out, "no_release %llu\n", (unsigned long long)edge);
            break;
        }
        if (released && !top->eth_rst_n) {
            fprintf(out, "reset_again %llu\n", (unsigned long long)edge);
            break;
        }
        if (released && edge >= end) break;
    }
    if (in_frame) fprintf(out, "cut_frame %llu %s\n", (unsigned long long)frame_edge, frame.c_str());
    fprintf(out, "mdc_period %llu %llu\n", (unsigned long long)(mdc_min == ~0ull ? 0 : mdc_min),
            (unsigned long long)mdc_max);
    fprintf(out, "end %llu\n", (unsigned long long)edge);
    fclose(out);
    top->final();
    delete top;
    return 0;
}
