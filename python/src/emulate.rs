//! `Emulator`: `skinbox emulate` in a thread of this process.

use crate::errors::{value_error, EmulatorError};
use pyo3::prelude::*;
use skinbox_emulator::{self as emulator, EmulatorSettings, ServeSummary};
use skinbox_model::emulator::EmulatorStats;
use std::net::{SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// An emulated box serving on a UDP socket in a thread until stopped.
#[pyclass(module = "skinbox")]
pub struct Emulator {
    address: SocketAddr,
    scene: String,
    ports: usize,
    stop: Arc<AtomicBool>,
    running: Arc<Mutex<EmulatorStats>>,
    thread: Mutex<Option<JoinHandle<std::io::Result<ServeSummary>>>>,
    summary: Mutex<Option<String>>,
}

fn summary_json(s: &ServeSummary) -> String {
    serde_json::to_string(s).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}

#[pymethods]
impl Emulator {
    /// Prepares the scene (which takes a moment) and starts the box on `listen`.
    #[new]
    #[pyo3(signature = (scene=None, listen="127.0.0.1:0", speed=1.0, from_ms=1000.0, duration_ms=10000.0, buses=None, cells=None, flush_timeout_us=100.0, status_period_ms=100.0, box_id=1))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        scene: Option<String>,
        listen: &str,
        speed: f64,
        from_ms: f64,
        duration_ms: f64,
        buses: Option<usize>,
        cells: Option<usize>,
        flush_timeout_us: f64,
        status_period_ms: f64,
        box_id: u16,
    ) -> PyResult<Self> {
        if !(speed > 0.0 && speed.is_finite()) {
            return Err(value_error(format!(
                "speed {speed}: must be a positive number"
            )));
        }
        if !(duration_ms > 0.0 && from_ms >= 0.0) {
            return Err(value_error(
                "duration_ms must be positive and from_ms not negative",
            ));
        }
        let listen: SocketAddrV4 = listen
            .parse()
            .map_err(|e| value_error(format!("listen {listen}: an IPv4 address and port: {e}")))?;
        let settings = EmulatorSettings {
            scene,
            from_ms,
            duration_ms,
            buses,
            cells,
            flush_timeout_us,
            status_period_ms,
            box_id,
            ..EmulatorSettings::default()
        };
        let socket = UdpSocket::bind(listen)
            .map_err(|e| EmulatorError::new_err(format!("binding {listen}: {e}")))?;
        let address = socket
            .local_addr()
            .map_err(|e| EmulatorError::new_err(e.to_string()))?;
        let SocketAddr::V4(bound) = address else {
            return Err(EmulatorError::new_err("bound to no IPv4 address"));
        };
        // The box's own address is the one bound (a port of 0 is chosen now).
        let prepared = py
            .detach(|| emulator::prepare(&settings, bound))
            .map_err(|e| EmulatorError::new_err(e.to_string()))?;
        let stop = Arc::new(AtomicBool::new(false));
        let running = Arc::new(Mutex::new(EmulatorStats::default()));
        let (scene, ports) = (prepared.scene.clone(), prepared.ports);
        let thread = {
            let (stop, running) = (stop.clone(), running.clone());
            std::thread::Builder::new()
                .name("skinbox-emulator".into())
                .spawn(move || {
                    emulator::serve(&prepared, &socket, speed, &stop, None, &mut |s| {
                        if let Ok(mut r) = running.lock() {
                            *r = *s;
                        }
                    })
                })
                .map_err(|e| EmulatorError::new_err(e.to_string()))?
        };
        Ok(Emulator {
            address,
            scene,
            ports,
            stop,
            running,
            thread: Mutex::new(Some(thread)),
            summary: Mutex::new(None),
        })
    }

    /// The box's command address ("127.0.0.1:PORT").
    #[getter]
    fn address(&self) -> String {
        self.address.to_string()
    }

    /// The scene's name.
    #[getter]
    fn scene(&self) -> String {
        self.scene.clone()
    }

    /// The box's ports.
    #[getter]
    fn ports(&self) -> usize {
        self.ports
    }

    /// What the box did so far: datagrams and records sent, commands, acknowledgements.
    fn stats(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let stats = *self
            .running
            .lock()
            .map_err(|_| EmulatorError::new_err("the emulator's thread failed"))?;
        crate::json_to_python(
            py,
            &serde_json::to_string(&stats).map_err(|e| value_error(e.to_string()))?,
        )
    }

    /// Stops the box (waiting for its thread) and returns its summary: wall time, box
    /// ticks, what it sent, its counters. Stopping again returns the same summary.
    fn stop(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.stop.store(true, Ordering::Relaxed);
        let thread = self
            .thread
            .lock()
            .map_err(|_| EmulatorError::new_err("the emulator's thread failed"))?
            .take();
        let mut summary = self
            .summary
            .lock()
            .map_err(|_| EmulatorError::new_err("the emulator's thread failed"))?;
        if let Some(thread) = thread {
            let served = py
                .detach(|| thread.join())
                .map_err(|_| EmulatorError::new_err("the emulator's thread panicked"))?
                .map_err(|e| EmulatorError::new_err(format!("receiving commands: {e}")))?;
            *summary = Some(summary_json(&served));
        }
        match summary.as_deref() {
            Some(s) => crate::json_to_python(py, s),
            None => Err(EmulatorError::new_err("the emulator did not run")),
        }
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&self, py: Python<'_>, _args: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<bool> {
        self.stop(py)?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!(
            "skinbox.Emulator(scene='{}', address='{}', ports={})",
            self.scene, self.address, self.ports
        )
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}
