//! A Foxglove WebSocket server (protocol `foxglove.websocket.v1`) for the live view: it
//! advertises one channel per [`Topic`] (`cdr` messages with their `ros2msg` schema, the
//! `.msg` files) and sends each subscribed client every message. Each client has its own
//! thread and a bounded queue: a slow client loses messages (counted), never the capture.

use crate::sink::{Output, Topic};
use std::io;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tungstenite::handshake::server::{Request, Response};
use tungstenite::{Message, WebSocket};

/// The WebSocket subprotocol.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Messages queued per client before it loses some.
pub const CLIENT_QUEUE: usize = 4096;

type Item = (Topic, u64, Arc<[u8]>);

/// The server: an [`Output`] that sends to every connected client.
pub struct FoxgloveServer {
    addr: SocketAddr,
    clients: Arc<Mutex<Vec<SyncSender<Item>>>>,
    dropped: Arc<AtomicU64>,
}

/// The channel id of a topic.
fn channel_id(topic: Topic) -> u32 {
    topic.index() as u32 + 1
}

fn advertise() -> String {
    let channels: Vec<serde_json::Value> = Topic::ALL
        .iter()
        .map(|t| {
            serde_json::json!({
                "id": channel_id(*t),
                "topic": t.name(),
                "encoding": "cdr",
                "schemaName": t.type_name(),
                "schema": t.schema(),
                "schemaEncoding": "ros2msg",
            })
        })
        .collect();
    serde_json::json!({"op": "advertise", "channels": channels}).to_string()
}

impl FoxgloveServer {
    /// Listens on `addr` (port 0: a free port, see [`FoxgloveServer::local_addr`]).
    pub fn start(addr: SocketAddr) -> io::Result<FoxgloveServer> {
        let listener = TcpListener::bind(addr)
            .map_err(|e| io::Error::new(e.kind(), format!("foxglove server on {addr}: {e}")))?;
        let addr = listener.local_addr()?;
        let clients: Arc<Mutex<Vec<SyncSender<Item>>>> = Arc::default();
        let registry = clients.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let (tx, rx) = sync_channel(CLIENT_QUEUE);
                if let Ok(mut c) = registry.lock() {
                    c.push(tx);
                }
                std::thread::spawn(move || {
                    let _ = serve_client(stream, rx);
                });
            }
        });
        Ok(FoxgloveServer {
            addr,
            clients,
            dropped: Arc::default(),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Messages not sent to a client whose queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

impl Output for FoxgloveServer {
    fn publish(&mut self, topic: Topic, log_time_ns: u64, cdr: &[u8]) -> io::Result<()> {
        let Ok(mut clients) = self.clients.lock() else {
            return Ok(());
        };
        if clients.is_empty() {
            return Ok(());
        }
        let bytes: Arc<[u8]> = Arc::from(cdr);
        clients.retain(|c| match c.try_send((topic, log_time_ns, bytes.clone())) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        });
        Ok(())
    }
}

// The handshake callback's error type is tungstenite's.
#[allow(clippy::result_large_err)]
fn serve_client(stream: TcpStream, rx: Receiver<Item>) -> Result<(), Box<dyn std::error::Error>> {
    stream.set_nodelay(true)?;
    let mut ws: WebSocket<TcpStream> =
        tungstenite::accept_hdr(stream, |_req: &Request, mut resp: Response| {
            resp.headers_mut().insert(
                "Sec-WebSocket-Protocol",
                tungstenite::http::HeaderValue::from_static(SUBPROTOCOL),
            );
            Ok(resp)
        })?;
    let info = serde_json::json!({
        "op": "serverInfo",
        "name": "skinbox",
        "capabilities": [],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": format!("{}", std::process::id()),
    });
    ws.send(Message::text(info.to_string()))?;
    ws.send(Message::text(advertise()))?;
    ws.get_ref()
        .set_read_timeout(Some(Duration::from_millis(5)))?;
    // subscription id by channel
    let mut subscriptions: Vec<(u32, u32)> = Vec::new();
    loop {
        match ws.read() {
            Ok(Message::Text(text)) => take_request(text.as_str(), &mut subscriptions),
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return Err(e.into()),
        }
        let mut sent = false;
        loop {
            let (topic, time, bytes) = match rx.try_recv() {
                Ok(item) => item,
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
                Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                    let _ = ws.close(None);
                    let _ = ws.flush();
                    return Ok(());
                }
            };
            for (sub, _) in subscriptions
                .iter()
                .filter(|(_, c)| *c == channel_id(topic))
            {
                let mut frame = Vec::with_capacity(13 + bytes.len());
                frame.push(0x01);
                frame.extend_from_slice(&sub.to_le_bytes());
                frame.extend_from_slice(&time.to_le_bytes());
                frame.extend_from_slice(&bytes);
                ws.write(Message::binary(frame))?;
                sent = true;
            }
        }
        if sent {
            ws.flush()?;
        }
    }
}

/// A client's `subscribe` or `unsubscribe` (others are ignored, as bad JSON is).
fn take_request(text: &str, subscriptions: &mut Vec<(u32, u32)>) {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(text) else {
        return;
    };
    match v["op"].as_str() {
        Some("subscribe") => {
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                if let (Some(id), Some(ch)) = (s["id"].as_u64(), s["channelId"].as_u64()) {
                    subscriptions.push((id as u32, ch as u32));
                }
            }
        }
        Some("unsubscribe") => {
            let ids: Vec<u64> = v["subscriptionIds"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|x| x.as_u64())
                .collect();
            subscriptions.retain(|(id, _)| !ids.contains(&u64::from(*id)));
        }
        _ => {}
    }
}
