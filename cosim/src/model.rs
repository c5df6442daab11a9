//! Building, caching and loading verilated models of the box.

use crate::binding::Library;
use crate::cache_lock::CacheLock;
use skinbox_gateware::interface_box::{verilog, BoxConfig, ConfigError};
use skinbox_gateware::verilog::LINT_WAIVERS;
use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};

/// Why a model could not be built or loaded.
#[derive(Debug, thiserror::Error)]
pub enum CosimError {
    /// The box parameters are impossible.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Verilator is not installed.
    #[error("verilator not found ({0}): install it with 'apt-get install -y verilator' (scripts/test and scripts/run do)")]
    NoVerilator(std::io::Error),
    /// Verilator, the C++ compiler or the linker failed.
    #[error("{step} failed:\n{output}")]
    Tool { step: &'static str, output: String },
    /// Reading or writing the cache.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The shared library could not be loaded.
    #[error("loading {path}: {message}")]
    Load { path: PathBuf, message: String },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CosimError + '_ {
    move |source| CosimError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Verilator flags for every model (DESIGN.md section 6); `--threads 1` because more threads
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

// Builds from several threads wait for each other (and, by `CacheLock`, for other processes).
static BUILD_LOCK: Mutex<()> = Mutex::new(());

impl Model {
    /// The model of `config` (with VCD tracing compiled in when `trace`), from the cache in
    /// `cache_dir` or built into it.
    pub fn build(
        config: &BoxConfig,
        trace: bool,
        cache_dir: &Path,
    ) -> Result<Arc<Model>, CosimError> {
        let text = verilog(config)?;
        let version = verilator_version()?;
        let mut hasher = DefaultHasher::new();
        (&text, trace, &version, SHIM_VERSION).hash(&mut hasher);
        let dir = cache_dir.join(format!("box{}-{:016x}", config.ports, hasher.finish()));
        let library_path = dir.join("libbox.so");
        let mut built_here = false;
        if !library_path.exists() {
            let _guard = BUILD_LOCK.lock().unwrap_or_else(|e| e.into_inner());
            // other processes wait here too; the first builds, the rest find its model
            let _cache_lock = CacheLock::acquire(&dir)?;
            if !library_path.exists() {
                built_here = true;
                let runtime = build_runtime(cache_dir, &version, trace)?;
                let built = build_model(&text, config.ports, trace, &dir, &runtime);
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

/// Bumped when the shim changes, so cached models are rebuilt.
const SHIM_VERSION: u32 = 1;

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

/// Verilator's runtime objects, compiled once per Verilator version and trace option.
fn build_runtime(cache_dir: &Path, version: &str, trace: bool) -> Result<Vec<PathBuf>, CosimError> {
    let mut hasher = DefaultHasher::new();
    (version, trace).hash(&mut hasher);
    let dir = cache_dir.join(format!("runtime-{:016x}", hasher.finish()));
    let list = dir.join("objects.txt");
    let _lock = CacheLock::acquire(&dir)?;
    if let Ok(text) = std::fs::read_to_string(&list) {
        return Ok(text.lines().map(PathBuf::from).collect());
    }
    std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    let include = verilator_include();
    let mut build = compiler(&dir);
    build
        .file(include.join("verilated.cpp"))
        .file(include.join("verilated_threads.cpp"));
    if trace {
        build
            .file(include.join("verilated_vcd_c.cpp"))
            .define("VM_TRACE", "1");
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
    ports: usize,
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
    command.args(VERILATOR_FLAGS);
    for waiver in LINT_WAIVERS {
        command.arg(format!("-Wno-{waiver}"));
    }
    if trace {
        command.arg("--trace");
    }
    command.arg("-Mdir").arg(&obj).arg(&source);
    let out = command.output().map_err(CosimError::NoVerilator)?;
    if !out.status.success() {
        return Err(CosimError::Tool {
            step: "verilator",
            output: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }

    let shim = work.join("shim.cpp");
    std::fs::write(&shim, shim_source(ports, trace)).map_err(io(&shim))?;
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
    let pins: Vec<String> = (0..ports)
        .map(|p| format!("&top->uart_rx__024{p}"))
        .collect();
    let trace_include = if trace {
        "#include \"verilated_vcd_c.h\""
    } else {
        ""
    };
    let trace_open = if trace {
        "if (vcd_path && vcd_path[0]) { ctx->traceEverOn(true); d->vcd = new VerilatedVcdC; top->trace(d->vcd, 99); d->vcd->open(vcd_path); }"
    } else {
        ""
    };
    let trace_dump = if trace {
        "if (d->vcd) d->vcd->dump(d->time);"
    } else {
        ""
    };
    let trace_close = if trace {
        "if (d->vcd) { d->vcd->close(); delete d->vcd; }"
    } else {
        ""
    };
    format!(
        r#"// Generated by skinbox-cosim: C entry points into the verilated box.
#include "Vtop.h"
#include "verilated.h"
#include <cstdint>
{trace_include}

struct Dut {{
    VerilatedContext* ctx;
    Vtop* top;
    CData* rx[{ports}];
    uint64_t time;
    {vcd_member}
}};

extern "C" {{

uint32_t skinbox_ports() {{ return {ports}; }}

void* skinbox_new(const char* vcd_path) {{
    Dut* d = new Dut();
    VerilatedContext* ctx = new VerilatedContext;
    d->ctx = ctx;
    Vtop* top = new Vtop(ctx);
    d->top = top;
    CData* pins[{ports}] = {{ {pins} }};
    for (int i = 0; i < {ports}; i++) {{ d->rx[i] = pins[i]; *pins[i] = 1; }}
    top->clock = 0;
    top->reset = 1;
    d->time = 0;
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

uint64_t skinbox_run(void* p, uint64_t cycles, uint32_t* offsets, uint8_t* bytes,
                     uint64_t capacity, uint64_t* stored, uint64_t* tx_errors) {{
    Dut* d = (Dut*)p;
    Vtop* top = d->top;
    uint64_t n = 0, k = 0;
    for (; n < cycles && k < capacity; n++) {{
        top->clock = 1;
        top->eval();
        d->time += 4;
        {trace_dump}
        if (top->gmii_tx_en) {{ offsets[k] = (uint32_t)n; bytes[k] = top->gmii_txd; k++; }}
        if (top->gmii_tx_er) (*tx_errors)++;
        top->clock = 0;
        top->eval();
        d->time += 4;
        {trace_dump}
    }}
    *stored = k;
    return n;
}}

}}
"#,
        pins = pins.join(", "),
        vcd_member = if trace { "VerilatedVcdC* vcd;" } else { "" },
        vcd_init = if trace { "d->vcd = nullptr;" } else { "" },
    )
}
