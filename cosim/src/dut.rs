//! A safe handle to one simulated box.

use crate::binding::Instance;
use crate::error::CosimError;
use crate::model::Model;
use std::path::Path;
use std::sync::Arc;

/// One byte the box sent on GMII.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GmiiByte {
    /// Clock cycle (rising edges since the Dut was made) at which `gmii_txd` held it.
    pub cycle: u64,
    /// The byte.
    pub data: u8,
}

/// A change of one UART transmit pin (the downlink to the cells).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UartTxEdge {
    /// Rising clock edge (numbered as [`GmiiByte::cycle`]) after which the pin has `level`.
    pub edge: u64,
    /// The port.
    pub port: usize,
    /// The pin's new level.
    pub level: bool,
}

/// One simulated interface box: UART pins and reset in, GMII bytes out.
pub struct Dut {
    model: Arc<Model>,
    instance: Instance,
    cycle: u64,
    tx_errors: u64,
    offsets: Vec<u32>,
    bytes: Vec<u8>,
    /// The edge after which GMII receive is free again (the last queued frame's end).
    rx_free_from: u64,
}

const BUFFER: usize = 1 << 16;

impl Dut {
    /// A new box in reset, all pins idle (high). With `vcd`, the model must have tracing.
    pub fn new(model: &Arc<Model>, vcd: Option<&Path>) -> Result<Dut, CosimError> {
        if vcd.is_some() && !model.has_trace() {
            return Err(CosimError::Load {
                path: vcd.unwrap_or(Path::new("")).to_path_buf(),
                message: "VCD requested from a model built without tracing".into(),
            });
        }
        let instance = Instance::new(&model.library, vcd)?;
        Ok(Dut {
            model: model.clone(),
            instance,
            cycle: 0,
            tx_errors: 0,
            offsets: vec![0; BUFFER],
            bytes: vec![0; BUFFER],
            rx_free_from: 0,
        })
    }

    /// Number of UART ports.
    pub fn ports(&self) -> usize {
        self.model.config().ports
    }

    /// Rising clock edges so far.
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Clocks with `gmii_tx_er` high so far (the box never sets it).
    pub fn tx_errors(&self) -> u64 {
        self.tx_errors
    }

    /// Drives UART pin `port` (panics when out of range: a harness bug).
    pub fn set_rx(&mut self, port: usize, level: bool) {
        assert!(
            port < self.ports(),
            "port {port} of a {}-port box",
            self.ports()
        );
        self.instance
            .set_rx(&self.model.library, port as u32, level);
    }

    /// Drives the synchronous reset.
    pub fn set_reset(&mut self, on: bool) {
        self.instance.set_reset(&self.model.library, on);
    }

    /// Drives `wire` (a frame as it is on the wire: preamble, SFD, frame, FCS) on GMII
    /// receive, one byte per clock, the first byte sampled by rising edge `start` (the
    /// cycle numbering of [`GmiiByte`]). Fails when `start` is not after the frame queued
    /// before it (its last byte and at least one idle clock) or not in the future.
    pub fn queue_rx_frame(&mut self, start: u64, wire: &[u8]) -> Result<(), String> {
        if start <= self.cycle || start <= self.rx_free_from {
            return Err(format!(
                "receive frame at edge {start}: GMII receive is busy or that edge has passed \
                 (cycle {}, receive free after edge {})",
                self.cycle, self.rx_free_from
            ));
        }
        if wire.is_empty() {
            return Err("receive frame of no bytes".into());
        }
        self.instance.queue_rx(&self.model.library, start, wire);
        self.rx_free_from = start + wire.len() as u64;
        Ok(())
    }

    /// The UART transmit pin changes since the last call, oldest first (the first calls
    /// show the pins going high at reset).
    pub fn take_uart_tx_edges(&mut self) -> Vec<UartTxEdge> {
        let mut out = Vec::new();
        let (mut edges, mut ports, mut levels) = (vec![0; 4096], vec![0; 4096], vec![0; 4096]);
        loop {
            let n = self
                .instance
                .take_tx(&self.model.library, &mut edges, &mut ports, &mut levels);
            out.extend((0..n).map(|i| UartTxEdge {
                edge: edges[i],
                port: ports[i] as usize,
                level: levels[i] != 0,
            }));
            if n < edges.len() {
                return out;
            }
        }
    }

    /// Runs `cycles` clock cycles with the inputs held, passing every GMII byte to `sink`.
    pub fn run(&mut self, cycles: u64, mut sink: impl FnMut(GmiiByte)) {
        let mut left = cycles;
        while left > 0 {
            let (ran, stored, errors) = self.instance.run(
                &self.model.library,
                left,
                &mut self.offsets,
                &mut self.bytes,
            );
            for (offset, data) in self.offsets[..stored].iter().zip(&self.bytes[..stored]) {
                sink(GmiiByte {
                    cycle: self.cycle + u64::from(*offset) + 1,
                    data: *data,
                });
            }
            self.tx_errors += errors;
            self.cycle += ran;
            left -= ran;
        }
    }
}

impl Drop for Dut {
    fn drop(&mut self) {
        self.instance.free(&self.model.library);
    }
}
