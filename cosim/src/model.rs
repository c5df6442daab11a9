//! Building, caching and loading verilated models of the box.

use crate::binding::Library;
use crate::cache_lock::CacheLock;
use crate::error::CosimError;
use sha2::{Digest, Sha256};
use skinbox_gateware::interface_box::{verilog, BoxConfig};
use skinbox_gateware::verilog::LINT_WAIVERS;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CosimError + '_ {
    move |source| CosimError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Verilator flags for every model (docs/design.md section 6); `--threads 1` because more threads
/// slow a design this small down.
pub const VERILATOR_FLAGS: &[&str] = &[
    "--cc",
    "-O3",
    "--x-assign",
    "fast",
    "--x-initial",
    "fast",
    "--noassert",
    "--threads",
    "1",
    "--top-module",
    "top",
];

/// Where models are cached: `$SKINBOX_BUILD_DIR/verilated`, else `build/verilated` in the
/// workspace.
pub fn default_cache_dir() -> PathBuf {
    std::env::var_os("SKINBOX_BUILD_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../build"))
        .join("verilated")
}

/// A loaded model of one box configuration.
pub struct Model {
    pub(crate) library: Library,
    config: BoxConfig,
    trace: bool,
    path: PathBuf,
    built: bool,
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Model")
            .field("ports", &self.config.ports)
            .field("trace", &self.trace)
            .field("path", &self.path)
            .finish()
    }
}

/// The runtime's key on this machine, with and without tracing: probing the toolchain and
/// hashing the runtime sources once per process, not at every model load.
fn runtime_key(trace: bool) -> Result<String, CosimError> {
    static KEYS: [std::sync::OnceLock<String>; 2] =
        [std::sync::OnceLock::new(), std::sync::OnceLock::new()];
    let slot = &KEYS[usize::from(trace)];
    if let Some(key) = slot.get() {
        return Ok(key.clone());
    }
    let key = RuntimeInputs::of_this_machine(trace)?.key();
    Ok(slot.get_or_init(|| key).clone())
}

impl Model {
    /// The model of `config` (with VCD tracing compiled in when `trace`), from the cache in
    /// `cache_dir` or built into it.
    pub fn build(
        config: &BoxConfig,
        trace: bool,
        cache_dir: &Path,
    ) -> Result<Arc<Model>, CosimError> {
        let verilog = verilog(config)?;
        let shim = shim_source(config.ports, trace);
        let runtime_key = runtime_key(trace)?;
        let key = ModelInputs {
            verilog: &verilog,
            shim: &shim,
            verilator_args: &verilator_args(trace),
            runtime_key: &runtime_key,
        }
        .key();
        let dir = cache_dir.join(format!("box{}-{key}", config.ports));
        let library_path = dir.join("libbox.so");
        let mut built_here = false;
        if !library_path.exists() {
            // other threads and processes wait here (each takes the lock through its own
            // open file); the first builds, the rest find its model
            let _cache_lock = CacheLock::acquire(&dir)?;
            if !library_path.exists() {
                built_here = true;
                let objects =
                    build_runtime(&cache_dir.join(format!("runtime-{runtime_key}")), trace)?;
                let built = build_model(&verilog, &shim, trace, &dir, &objects);
                // a failed build leaves no scratch directory behind
                std::fs::remove_dir_all(dir.with_extension(format!("tmp{}", std::process::id())))
                    .ok();
                built?;
            }
        }
        let library = Library::open(&library_path, config.ports)?;
        Ok(Arc::new(Model {
            library,
            config: config.clone(),
            trace,
            path: library_path,
            built: built_here,
        }))
    }

    /// The shared library loaded.
    pub fn library_path(&self) -> &Path {
        &self.path
    }

    /// Whether this call built the model (false: it was in the cache, perhaps built by
    /// another process that this one waited for).
    pub fn was_built(&self) -> bool {
        self.built
    }

    /// The box parameters.
    pub fn config(&self) -> &BoxConfig {
        &self.config
    }

    /// Whether VCD tracing is compiled in.
    pub fn has_trace(&self) -> bool {
        self.trace
    }
}

/// A cache key: SHA-256 over named parts, each written as its name, a zero byte, its length
/// (u64, little-endian) and its bytes, so that different inputs never hash the same bytes;
/// the first 16 bytes of the digest in hex. Stable across Rust releases and machines.
pub fn cache_key(parts: &[(&str, &[u8])]) -> String {
    let mut hash = Sha256::new();
    for (name, bytes) in parts {
        hash.update(name.as_bytes());
        hash.update([0]);
        hash.update((bytes.len() as u64).to_le_bytes());
        hash.update(bytes);
    }
    hash.finalize()[..16]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Everything a model build reads: its cache key covers all of it.
#[derive(Debug, Clone, Copy)]
pub struct ModelInputs<'a> {
    /// The box's Verilog.
    pub verilog: &'a str,
    /// The C++ shim's source.
    pub shim: &'a str,
    /// Verilator's arguments (flags and lint waivers).
    pub verilator_args: &'a [String],
    /// The key of the Verilator runtime it links ([`RuntimeInputs::key`]), which covers
    /// Verilator's version and the C++ compiler.
    pub runtime_key: &'a str,
}

impl ModelInputs<'_> {
    /// The cache key of the model.
    pub fn key(&self) -> String {
        cache_key(&[
            ("verilog", self.verilog.as_bytes()),
            ("shim", self.shim.as_bytes()),
            (
                "verilator arguments",
                self.verilator_args.join("\0").as_bytes(),
            ),
            ("runtime", self.runtime_key.as_bytes()),
        ])
    }
}

/// Everything a build of Verilator's runtime reads.
#[derive(Debug, Clone)]
pub struct RuntimeInputs {
    /// `verilator --version`.
    pub verilator_version: String,
    /// The C++ compiler: its path, arguments and `--version`.
    pub compiler: String,
    /// Whether VCD tracing is compiled in.
    pub trace: bool,
    /// The runtime's source files (name, text).
    pub sources: Vec<(String, Vec<u8>)>,
}

impl RuntimeInputs {
    /// The inputs as found on this machine.
    pub fn of_this_machine(trace: bool) -> Result<RuntimeInputs, CosimError> {
        let compiler = compiler(Path::new(".")).get_compiler();
        let version = compiler
            .to_command()
            .arg("--version")
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
            .unwrap_or_default();
        let args: Vec<String> = compiler
            .args()
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        let sources = runtime_sources(trace)
            .into_iter()
            .map(|path| {
                let text = std::fs::read(&path).map_err(io(&path))?;
                Ok((path.display().to_string(), text))
            })
            .collect::<Result<_, CosimError>>()?;
        Ok(RuntimeInputs {
            verilator_version: verilator_version()?,
            compiler: format!(
                "{}\n{}\n{}",
                compiler.path().display(),
                args.join(" "),
                version
            ),
            trace,
            sources,
        })
    }

    /// The cache key of the runtime objects.
    pub fn key(&self) -> String {
        let mut parts: Vec<(&str, &[u8])> = vec![
            ("verilator version", self.verilator_version.as_bytes()),
            ("compiler", self.compiler.as_bytes()),
            ("trace", if self.trace { b"1" } else { b"0" }),
        ];
        for (name, text) in &self.sources {
            parts.push((name, text));
        }
        cache_key(&parts)
    }
}

/// Verilator's runtime sources a model links.
fn runtime_sources(trace: bool) -> Vec<PathBuf> {
    let include = verilator_include();
    let mut files = vec![
        include.join("verilated.cpp"),
        include.join("verilated_threads.cpp"),
    ];
    if trace {
        files.push(include.join("verilated_vcd_c.cpp"));
    }
    files
}

/// Verilator's arguments besides the output directory and the source.
fn verilator_args(trace: bool) -> Vec<String> {
    let mut args: Vec<String> = VERILATOR_FLAGS.iter().map(|f| f.to_string()).collect();
    args.extend(LINT_WAIVERS.iter().map(|w| format!("-Wno-{w}")));
    if trace {
        args.push("--trace".into());
    }
    args
}

fn verilator_version() -> Result<String, CosimError> {
    let out = Command::new("verilator")
        .arg("--version")
        .output()
        .map_err(CosimError::NoVerilator)?;
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn verilator_include() -> PathBuf {
    std::env::var_os("VERILATOR_ROOT")
        .map(|r| PathBuf::from(r).join("include"))
        .unwrap_or_else(|| PathBuf::from("/usr/share/verilator/include"))
}

fn compiler(out_dir: &Path) -> cc::Build {
    let target = env!("SKINBOX_COSIM_TARGET");
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .opt_level(2)
        .pic(true)
        .debug(false)
        .warnings(false)
        .cargo_metadata(false)
        .cargo_warnings(false)
        .target(target)
        .host(target)
        .out_dir(out_dir)
        .include(verilator_include())
        .include(verilator_include().join("vltstd"));
    build
}

fn tool_error(step: &'static str) -> impl FnOnce(cc::Error) -> CosimError {
    move |e| CosimError::Tool {
        step,
        output: e.to_string(),
    }
}

/// Verilator's runtime objects in `dir`, compiled once per [`RuntimeInputs::key`].
fn build_runtime(dir: &Path, trace: bool) -> Result<Vec<PathBuf>, CosimError> {
    let list = dir.join("objects.txt");
    let _lock = CacheLock::acquire(dir)?;
    if let Ok(text) = std::fs::read_to_string(&list) {
        return Ok(text.lines().map(PathBuf::from).collect());
    }
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut build = compiler(dir);
    build.files(runtime_sources(trace));
    if trace {
        build.define("VM_TRACE", "1");
    }
    let objects = build
        .try_compile_intermediates()
        .map_err(tool_error("compiling the Verilator runtime"))?;
    let text: Vec<String> = objects.iter().map(|p| p.display().to_string()).collect();
    std::fs::write(&list, text.join("\n")).map_err(io(&list))?;
    Ok(objects)
}

/// Verilates `verilog`, compiles it with the shim and links `dir/libbox.so`.
fn build_model(
    verilog: &str,
    shim_text: &str,
    trace: bool,
    dir: &Path,
    runtime: &[PathBuf],
) -> Result<(), CosimError> {
    let work = dir.with_extension(format!("tmp{}", std::process::id()));
    if work.exists() {
        std::fs::remove_dir_all(&work).map_err(io(&work))?;
    }
    let obj = work.join("obj");
    std::fs::create_dir_all(&obj).map_err(io(&obj))?;
    let source = work.join("top.v");
    std::fs::write(&source, verilog).map_err(io(&source))?;

    let mut command = Command::new("verilator");
    command.args(verilator_args(trace));
    command.arg("-Mdir").arg(&obj).arg(&source);
    let out = command.output().map_err(CosimError::NoVerilator)?;
    if !out.status.success() {
        return Err(CosimError::Tool {
            step: "verilator",
            output: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }

    let shim = work.join("shim.cpp");
    std::fs::write(&shim, shim_text).map_err(io(&shim))?;
    let mut build = compiler(&work);
    build.include(&obj).file(&shim);
    if trace {
        build.define("VM_TRACE", "1");
    }
    let mut sources: Vec<PathBuf> = std::fs::read_dir(&obj)
        .map_err(io(&obj))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "cpp"))
        .collect();
    sources.sort();
    build.files(&sources);
    let objects = build
        .try_compile_intermediates()
        .map_err(tool_error("compiling the verilated model"))?;

    let library = work.join("libbox.so");
    let mut link = compiler(&work).get_compiler().to_command();
    link.arg("-shared")
        .arg("-o")
        .arg(&library)
        .args(&objects)
        .args(runtime)
        .arg("-pthread");
    let out = link.output().map_err(io(&library))?;
    if !out.status.success() {
        return Err(CosimError::Tool {
            step: "linking the model",
            output: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }
    // publish atomically: another process may have finished the same model meanwhile
    if std::fs::rename(&work, dir).is_err() && !dir.join("libbox.so").exists() {
        return Err(CosimError::Io {
            path: dir.to_path_buf(),
            source: std::io::Error::other("could not move the built model into the cache"),
        });
    }
    std::fs::remove_dir_all(&work).ok();
    Ok(())
}

/// The C++ side of the binding: one instance of the verilated box behind plain C calls.
///
/// `skinbox_run` clocks the box `cycles` times (inputs held) and stores every clock with
/// `gmii_tx_en` high as (cycle offset, byte) so Rust sees the frames without a call per
/// clock; it stops early when the output buffer is full and returns the cycles run.
fn shim_source(ports: usize, trace: bool) -> String {
    // the trace's lines, empty without it
    let t = |line: &'static str| if trace { line } else { "" };
    [
        shim_declarations(ports, t),
        shim_lifecycle(ports, t),
        shim_run(ports, t),
    ]
    .concat()
}

/// The shim's includes and its state: the frames to drive, the transmit pins' edges.
fn shim_declarations(ports: usize, t: impl Fn(&'static str) -> &'static str) -> String {
    format!(
        r#"// Generated by skinbox-cosim: C entry points into the verilated box.
#include "Vtop.h"
#include "verilated.h"
#include <cstdint>
#include <deque>
#include <vector>
{trace_include}

// A frame to drive on GMII receive: its bytes (preamble to FCS) from edge `start` on.
struct RxFrame {{
    uint64_t start;
    std::vector<uint8_t> bytes;
}};

struct TxEdge {{
    uint64_t edge;
    uint32_t port;
    uint8_t level;
}};

struct Dut {{
    VerilatedContext* ctx;
    Vtop* top;
    CData* rx[{ports}];
    CData* tx[{ports}];
    uint8_t tx_level[{ports}];
    std::vector<TxEdge> tx_edges;
    size_t tx_taken;
    uint64_t time;
    // rising edges so far, and the receive frames not yet (completely) driven
    uint64_t edges;
    std::deque<RxFrame> rx_frames;
    size_t rx_at;
    {vcd_member}
}};

extern "C" {{

"#,
        trace_include = t("#include \"verilated_vcd_c.h\""),
        vcd_member = t("VerilatedVcdC* vcd;"),
    )
}

/// The entry points that make, free and set up a box.
fn shim_lifecycle(ports: usize, t: impl Fn(&'static str) -> &'static str) -> String {
    let pins = |name: &str| {
        (0..ports)
            .map(|p| format!("&top->{name}__024{p}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        r#"uint32_t skinbox_ports() {{ return {ports}; }}

void* skinbox_new(const char* vcd_path) {{
    Dut* d = new Dut();
    VerilatedContext* ctx = new VerilatedContext;
    d->ctx = ctx;
    Vtop* top = new Vtop(ctx);
    d->top = top;
    CData* pins[{ports}] = {{ {pins} }};
    for (int i = 0; i < {ports}; i++) {{ d->rx[i] = pins[i]; *pins[i] = 1; }}
    CData* tx_pins[{ports}] = {{ {tx_pins} }};
    for (int i = 0; i < {ports}; i++) {{ d->tx[i] = tx_pins[i]; d->tx_level[i] = 1; }}
    d->tx_taken = 0;
    top->clock = 0;
    top->reset = 1;
    top->link_up = {link_up};
    top->link_speed = {link_speed};
    top->gmii_rxd = 0;
    top->gmii_rx_dv = 0;
    top->gmii_rx_er = 0;
    d->time = 0;
    d->edges = 0;
    d->rx_at = 0;
    {vcd_init}
    {trace_open}
    top->eval();
    return d;
}}

void skinbox_free(void* p) {{
    Dut* d = (Dut*)p;
    {trace_close}
    d->top->final();
    delete d->top;
    delete d->ctx;
    delete d;
}}

void skinbox_set_rx(void* p, uint32_t port, uint8_t level) {{
    Dut* d = (Dut*)p;
    if (port < {ports}) *d->rx[port] = level ? 1 : 0;
}}

void skinbox_set_reset(void* p, uint8_t on) {{ ((Dut*)p)->top->reset = on ? 1 : 0; }}

void skinbox_queue_rx(void* p, uint64_t start, const uint8_t* bytes, uint64_t len) {{
    Dut* d = (Dut*)p;
    d->rx_frames.push_back(RxFrame{{start, std::vector<uint8_t>(bytes, bytes + len)}});
}}

"#,
        pins = pins("uart_rx"),
        tx_pins = pins("uart_tx"),
        link_up = u8::from(crate::harness::LINK_UP),
        link_speed = crate::harness::LINK_SPEED as u8,
        vcd_init = t("d->vcd = nullptr;"),
        trace_open = t("if (vcd_path && vcd_path[0]) { ctx->traceEverOn(true); d->vcd = new VerilatedVcdC; top->trace(d->vcd, 99); d->vcd->open(vcd_path); }"),
        trace_close = t("if (d->vcd) { d->vcd->close(); delete d->vcd; }"),
    )
}

/// The entry points that clock the box and hand its transmit pins' edges over.
fn shim_run(ports: usize, t: impl Fn(&'static str) -> &'static str) -> String {
    format!(
        r#"uint64_t skinbox_run(void* p, uint64_t cycles, uint32_t* offsets, uint8_t* bytes,
                     uint64_t capacity, uint64_t* stored, uint64_t* tx_errors) {{
    Dut* d = (Dut*)p;
    Vtop* top = d->top;
    uint64_t n = 0, k = 0;
    for (; n < cycles && k < capacity; n++) {{
        // the receive byte of this edge (queued frames are in edge order, apart)
        d->edges++;
        top->gmii_rx_dv = 0;
        if (!d->rx_frames.empty() && d->edges >= d->rx_frames.front().start) {{
            RxFrame& f = d->rx_frames.front();
            top->gmii_rx_dv = 1;
            top->gmii_rxd = f.bytes[d->rx_at++];
            if (d->rx_at == f.bytes.size()) {{ d->rx_frames.pop_front(); d->rx_at = 0; }}
        }}
        top->clock = 1;
        top->eval();
        d->time += 4;
        {trace_dump}
        if (top->gmii_tx_en) {{ offsets[k] = (uint32_t)n; bytes[k] = top->gmii_txd; k++; }}
        for (int i = 0; i < {ports}; i++) {{
            if (*d->tx[i] != d->tx_level[i]) {{
                d->tx_level[i] = *d->tx[i];
                d->tx_edges.push_back(TxEdge{{d->edges, (uint32_t)i, d->tx_level[i]}});
            }}
        }}
        if (top->gmii_tx_er) (*tx_errors)++;
        top->clock = 0;
        top->eval();
        d->time += 4;
        {trace_dump}
    }}
    *stored = k;
    return n;
}}

uint64_t skinbox_take_tx(void* p, uint64_t* edges, uint32_t* ports, uint8_t* levels,
                         uint64_t capacity) {{
    Dut* d = (Dut*)p;
    uint64_t n = 0;
    while (n < capacity && d->tx_taken < d->tx_edges.size()) {{
        const TxEdge& e = d->tx_edges[d->tx_taken++];
        edges[n] = e.edge; ports[n] = e.port; levels[n] = e.level; n++;
    }}
    if (d->tx_taken == d->tx_edges.size()) {{ d->tx_edges.clear(); d->tx_taken = 0; }}
    return n;
}}

}}
"#,
        trace_dump = t("if (d->vcd) d->vcd->dump(d->time);"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cache_key_is_sha256_of_the_framed_parts() {
        // Python's hashlib over the same framing: name, 0, length as u64 little-endian, bytes.
        // sha256(b"verilog\0" + pack("<Q", 21) + b"module top; endmodule"
        //        + b"trace\0" + pack("<Q", 1) + b"1")
        assert_eq!(
            cache_key(&[("verilog", b"module top; endmodule"), ("trace", b"1")]),
            "611d621afb6a824a8a7c3ef66ca35191"
        );
        // No parts: the hash of nothing.
        assert_eq!(cache_key(&[]), "e3b0c44298fc1c149afbf4c8996fb924");
    }

    #[test]
    fn the_framing_keeps_parts_apart() {
        let key = |a: &str, b: &str| cache_key(&[("a", a.as_bytes()), ("b", b.as_bytes())]);
        assert_eq!(key("xy", "z"), key("xy", "z"));
        assert_ne!(key("xy", "z"), key("x", "yz"));
        assert_ne!(
            cache_key(&[("a", b"1")]),
            cache_key(&[("b", b"1")]),
            "names count"
        );
    }

    #[test]
    fn every_input_changes_the_keys() {
        let args = verilator_args(false);
        let base = ModelInputs {
            verilog: "module top; endmodule",
            shim: "shim",
            verilator_args: &args,
            runtime_key: "runtime",
        };
        let traced = verilator_args(true);
        let changed = [
            ModelInputs {
                verilog: "module top ; endmodule",
                ..base
            },
            ModelInputs {
                shim: "shim2",
                ..base
            },
            ModelInputs {
                verilator_args: &traced,
                ..base
            },
            ModelInputs {
                runtime_key: "runtime2",
                ..base
            },
        ];
        for other in changed {
            assert_ne!(other.key(), base.key(), "{other:?}");
        }
        assert_eq!(ModelInputs { ..base }.key(), base.key());

        let runtime = RuntimeInputs {
            verilator_version: "Verilator 5.006".into(),
            compiler: "c++ -O2".into(),
            trace: false,
            sources: vec![("verilated.cpp".into(), b"int x;".to_vec())],
        };
        let mut changed = vec![runtime.clone(); 4];
        changed[0].verilator_version = "Verilator 5.048".into();
        changed[1].compiler = "c++ -O3".into();
        changed[2].trace = true;
        changed[3].sources[0].1 = b"int y;".to_vec();
        for other in changed {
            assert_ne!(other.key(), runtime.key(), "{other:?}");
        }
    }

    #[test]
    fn the_shim_differs_with_ports_and_trace() {
        // The shim is hashed as text, so its ports and trace option reach the key.
        assert_ne!(shim_source(1, false), shim_source(2, false));
        assert_ne!(shim_source(1, false), shim_source(1, true));
    }
}
