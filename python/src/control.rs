//! `Box`: the commands of `skinbox ctl`, each acknowledged or raised.

use crate::errors::{value_error, BoxError, BoxRefusedError};
use pyo3::prelude::*;
use skinbox_host::control::{self, BoxClient, Exchange};
use skinbox_protocol::cell_command::{
    CellCommand, CellCommandRepr, CellMode, ModalityThresholds, SampleRate, ALL_CELLS,
};
use skinbox_protocol::command::{Destination, Request, ALL_PORTS};
use skinbox_protocol::{Channel, ChannelMask};
use std::net::{SocketAddr, SocketAddrV4, UdpSocket};
use std::time::Duration;

/// A box (or an emulated box) to command, at its command address.
#[pyclass(module = "skinbox", name = "Box")]
pub struct BoxHandle {
    socket: UdpSocket,
    address: SocketAddr,
    timeout: Duration,
    retries: u32,
    box_id: Option<u16>,
}

fn exchange_object(py: Python<'_>, exchange: &Exchange) -> PyResult<Py<PyAny>> {
    crate::json_to_python(py, &control::exchange_json(exchange).to_string())
}

fn parse_mac(s: &str) -> PyResult<[u8; 6]> {
    let parts: Vec<&str> = s.split(':').collect();
    let bad = || {
        value_error(format!(
            "MAC address {s}: expected six hex bytes a:b:c:d:e:f"
        ))
    };
    if parts.len() != 6 {
        return Err(bad());
    }
    let mut mac = [0u8; 6];
    for (m, p) in mac.iter_mut().zip(parts) {
        *m = u8::from_str_radix(p, 16).map_err(|_| bad())?;
    }
    Ok(mac)
}

fn cell_id_of(cell: Option<u16>) -> PyResult<u16> {
    match cell {
        None => Ok(ALL_CELLS),
        Some(id @ 1..=16_382) => Ok(id),
        Some(id) => Err(value_error(format!(
            "cell {id}: cell ids are 1..=16382 (None for all)"
        ))),
    }
}

impl BoxHandle {
    /// Sends `request` without the GIL; the acknowledgement, or the reason as an exception.
    fn send(&self, py: Python<'_>, request: Request) -> PyResult<Exchange> {
        let exchange = py
            .detach(|| {
                let mut client = BoxClient::new(&self.socket, self.address);
                client.timeout = self.timeout;
                client.retries = self.retries;
                if let Some(id) = self.box_id {
                    client.box_id = id;
                }
                client.send(request)
            })
            .map_err(|e| BoxError::new_err(e.to_string()))?;
        match control::refusal(&exchange) {
            Some(reason) => Err(BoxRefusedError::new_err(reason)),
            None => Ok(exchange),
        }
    }

    fn command(&self, py: Python<'_>, request: Request) -> PyResult<Py<PyAny>> {
        let exchange = self.send(py, request)?;
        exchange_object(py, &exchange)
    }

    fn cells(
        &self,
        py: Python<'_>,
        command: CellCommand,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        let packet = CellCommandRepr {
            cell_id: cell_id_of(cell)?,
            command,
        }
        .to_bytes();
        self.command(
            py,
            Request::CellCommand {
                port: port.unwrap_or(ALL_PORTS),
                packet,
            },
        )
    }
}

#[pymethods]
impl BoxHandle {
    /// A box at `address` ("host:port"); each command waits `timeout_ms` for its
    /// acknowledgement, `retries` times more; `box_id` addresses one box (default: any).
    #[new]
    #[pyo3(signature = (address, timeout_ms=250, retries=3, box_id=None, bind="0.0.0.0:0"))]
    fn new(
        address: &str,
        timeout_ms: u64,
        retries: u32,
        box_id: Option<u16>,
        bind: &str,
    ) -> PyResult<Self> {
        let addr = control::resolve_ipv4(address)
            .map_err(|e| value_error(format!("box address {address}: {e}")))?;
        let bind: SocketAddr = bind
            .parse()
            .map_err(|e| value_error(format!("bind {bind}: {e}")))?;
        let socket =
            UdpSocket::bind(bind).map_err(|e| BoxError::new_err(format!("binding {bind}: {e}")))?;
        Ok(BoxHandle {
            socket,
            address: addr,
            timeout: Duration::from_millis(timeout_ms.max(1)),
            retries,
            box_id,
        })
    }

    /// The box's command address.
    #[getter]
    fn address(&self) -> String {
        self.address.to_string()
    }

    /// The local address commands are sent from (a stream-to without `to` streams here).
    #[getter]
    fn local_address(&self) -> PyResult<String> {
        self.socket
            .local_addr()
            .map(|a| a.to_string())
            .map_err(|e| BoxError::new_err(e.to_string()))
    }

    /// A status report now; the acknowledgement carries the box counters.
    fn status(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.command(py, Request::StatusNow)
    }

    /// Sends the box's datagrams to `to` ("ip:port", with `mac`), or to this object's
    /// own socket when `to` is None.
    #[pyo3(signature = (to=None, mac="ff:ff:ff:ff:ff:ff"))]
    fn stream_to(&self, py: Python<'_>, to: Option<&str>, mac: &str) -> PyResult<Py<PyAny>> {
        let to = match to {
            None => None,
            Some(to) => {
                let addr: SocketAddrV4 = to
                    .parse()
                    .map_err(|e| value_error(format!("stream_to {to}: {e}")))?;
                Some(Destination {
                    mac: parse_mac(mac)?,
                    ip: addr.ip().octets(),
                    port: addr.port(),
                })
            }
        };
        self.command(py, Request::StreamTo { to })
    }

    /// Sets a run-time parameter: "flush-timeout-us" or "status-period-ms".
    fn set(&self, py: Python<'_>, parameter: &str, value: f64) -> PyResult<Py<PyAny>> {
        let request = control::set_request(parameter, value).map_err(value_error)?;
        self.command(py, request)
    }

    /// Reads the box's tick: host send ns, box receive and send ticks, host receive ns.
    fn time(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.command(py, Request::ReadTick)
    }

    /// `count` round trips of a status-now command; one result each.
    #[pyo3(signature = (count=4))]
    fn ping(&self, py: Python<'_>, count: u32) -> PyResult<Vec<Py<PyAny>>> {
        (0..count.max(1))
            .map(|_| self.command(py, Request::StatusNow))
            .collect()
    }

    /// Passes a 20-byte cell-network command packet to one port (None: all ports).
    #[pyo3(signature = (packet, port=None))]
    fn cell_command(&self, py: Python<'_>, packet: &[u8], port: Option<u8>) -> PyResult<Py<PyAny>> {
        let packet: [u8; 20] = packet
            .try_into()
            .map_err(|_| value_error(format!("cell packet: 20 bytes, got {}", packet.len())))?;
        self.command(
            py,
            Request::CellCommand {
                port: port.unwrap_or(ALL_PORTS),
                packet,
            },
        )
    }

    /// The cells' mode, "data" or "event", on one port and cell (None: all).
    #[pyo3(signature = (mode, port=None, cell=None))]
    fn cells_mode(
        &self,
        py: Python<'_>,
        mode: &str,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        let mode = match mode {
            "data" => CellMode::Data,
            "event" => CellMode::Event,
            other => {
                return Err(value_error(format!(
                    "mode {other}: the modes are data and event"
                )))
            }
        };
        self.cells(py, CellCommand::Mode(mode), port, cell)
    }

    /// The cells' sample rate: 62.5, 125, 250, 500 or 1000 Hz.
    #[pyo3(signature = (hz, port=None, cell=None))]
    fn cells_rate(
        &self,
        py: Python<'_>,
        hz: f64,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        let rate = SampleRate::from_hz(hz).ok_or_else(|| {
            value_error(format!(
                "rate {hz} Hz: the cells run at 62.5, 125, 250, 500 or 1000 Hz"
            ))
        })?;
        self.cells(py, CellCommand::SampleRate(rate), port, cell)
    }

    /// Send-on-delta thresholds per modality in host units (default: Table I).
    #[pyo3(signature = (accel_g=0.02, force=0.001, proximity=0.0001, temperature_c=0.5, port=None, cell=None))]
    #[allow(clippy::too_many_arguments)]
    fn cells_thresholds(
        &self,
        py: Python<'_>,
        accel_g: f64,
        force: f64,
        proximity: f64,
        temperature_c: f64,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        let thresholds = ModalityThresholds::from_units([accel_g, force, proximity, temperature_c])
            .ok_or_else(|| {
                value_error("thresholds: each must be >= 0 and at most 65535 raw steps")
            })?;
        self.cells(py, CellCommand::Thresholds(thresholds), port, cell)
    }

    /// The channels that send events, by name (see `CHANNELS`); an empty list: none.
    #[pyo3(signature = (channels, port=None, cell=None))]
    fn cells_enable(
        &self,
        py: Python<'_>,
        channels: Vec<String>,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        let mut mask = ChannelMask::EMPTY;
        for name in &channels {
            let channel = Channel::ALL
                .into_iter()
                .find(|c| c.name() == name)
                .ok_or_else(|| {
                    value_error(format!(
                        "unknown channel {name}; channels are {}",
                        Channel::ALL.map(|c| c.name()).join(", ")
                    ))
                })?;
            mask.insert(channel);
        }
        self.cells(py, CellCommand::EnableMask(mask), port, cell)
    }

    /// Time sync: the box tick at which the packet leaves the box.
    #[pyo3(signature = (tick, port=None, cell=None))]
    fn cells_sync(
        &self,
        py: Python<'_>,
        tick: u64,
        port: Option<u8>,
        cell: Option<u16>,
    ) -> PyResult<Py<PyAny>> {
        self.cells(py, CellCommand::TimeSync { box_tick: tick }, port, cell)
    }

    fn __repr__(&self) -> String {
        format!("skinbox.Box('{}')", self.address)
    }
}
