//! The only unsafe code of the crate: the C entry points of a loaded model.
//!
//! Safety rests on three facts: the symbols come from a shim this crate generated with
//! exactly these signatures (`model::shim_source`); a handle is used by one `Dut` at a
//! time (it is not `Sync`), and freed once, on drop; buffers passed to `run` are checked
//! for length here.

use crate::error::CosimError;
use std::ffi::{c_char, c_void, CString};
use std::path::Path;

type New = unsafe extern "C" fn(*const c_char) -> *mut c_void;
type Free = unsafe extern "C" fn(*mut c_void);
type SetRx = unsafe extern "C" fn(*mut c_void, u32, u8);
type SetReset = unsafe extern "C" fn(*mut c_void, u8);
type QueueRx = unsafe extern "C" fn(*mut c_void, u64, *const u8, u64);
type Run =
    unsafe extern "C" fn(*mut c_void, u64, *mut u32, *mut u8, u64, *mut u64, *mut u64) -> u64;
type Ports = unsafe extern "C" fn() -> u32;
type TakeTx = unsafe extern "C" fn(*mut c_void, *mut u64, *mut u32, *mut u8, u64) -> u64;

/// A loaded model library with its entry points.
pub(crate) struct Library {
    new: New,
    free: Free,
    set_rx: SetRx,
    set_reset: SetReset,
    queue_rx: QueueRx,
    run: Run,
    take_tx: TakeTx,
    // keeps the code mapped while the function pointers above are in use
    _library: libloading::Library,
}

impl Library {
    /// Loads `path` and checks that it models `ports` ports.
    pub(crate) fn open(path: &Path, ports: usize) -> Result<Library, CosimError> {
        let fail = |message: String| CosimError::Load {
            path: path.to_path_buf(),
            message,
        };
        // SAFETY: the library is one this crate built; its initialisers are Verilator's.
        let library = unsafe { libloading::Library::new(path) }.map_err(|e| fail(e.to_string()))?;
        // SAFETY: each symbol has the signature the shim declares for it.
        unsafe {
            let get = |name: &[u8]| -> Result<*const c_void, CosimError> {
                library
                    .get::<*const c_void>(name)
                    .map(|s| *s)
                    .map_err(|e| fail(e.to_string()))
            };
            let lib = Library {
                new: std::mem::transmute::<*const c_void, New>(get(b"skinbox_new")?),
                free: std::mem::transmute::<*const c_void, Free>(get(b"skinbox_free")?),
                set_rx: std::mem::transmute::<*const c_void, SetRx>(get(b"skinbox_set_rx")?),
                set_reset: std::mem::transmute::<*const c_void, SetReset>(get(
                    b"skinbox_set_reset",
                )?),
                queue_rx: std::mem::transmute::<*const c_void, QueueRx>(get(b"skinbox_queue_rx")?),
                run: std::mem::transmute::<*const c_void, Run>(get(b"skinbox_run")?),
                take_tx: std::mem::transmute::<*const c_void, TakeTx>(get(b"skinbox_take_tx")?),
                _library: library,
            };
            let ports_fn = std::mem::transmute::<*const c_void, Ports>(
                lib._library
                    .get::<*const c_void>(b"skinbox_ports")
                    .map(|s| *s)
                    .map_err(|e| fail(e.to_string()))?,
            );
            let built = ports_fn() as usize;
            if built != ports {
                return Err(fail(format!(
                    "the model has {built} ports, expected {ports}"
                )));
            }
            Ok(lib)
        }
    }
}

/// One instance of the box in a loaded library.
pub(crate) struct Instance {
    handle: *mut c_void,
}

impl Instance {
    /// A new instance in reset with idle pins; VCD to `vcd` when the model has tracing.
    pub(crate) fn new(library: &Library, vcd: Option<&Path>) -> Result<Instance, CosimError> {
        let path = CString::new(vcd.map(|p| p.display().to_string()).unwrap_or_default()).map_err(
            |_| CosimError::Load {
                path: vcd.unwrap_or(Path::new("")).to_path_buf(),
                message: "path contains a NUL byte".into(),
            },
        )?;
        // SAFETY: `new` copies nothing from the string after returning; it lives until then.
        let handle = unsafe { (library.new)(path.as_ptr()) };
        Ok(Instance { handle })
    }

    pub(crate) fn set_rx(&mut self, library: &Library, port: u32, level: bool) {
        // SAFETY: valid handle; the shim ignores ports out of range.
        unsafe { (library.set_rx)(self.handle, port, u8::from(level)) }
    }

    pub(crate) fn set_reset(&mut self, library: &Library, on: bool) {
        // SAFETY: valid handle.
        unsafe { (library.set_reset)(self.handle, u8::from(on)) }
    }

    /// Queues `bytes` to be driven on GMII receive from rising edge `start` on (edges
    /// counted from 1 since the instance was made), one per edge.
    pub(crate) fn queue_rx(&mut self, library: &Library, start: u64, bytes: &[u8]) {
        // SAFETY: valid handle; the shim copies `bytes.len()` bytes before returning.
        unsafe { (library.queue_rx)(self.handle, start, bytes.as_ptr(), bytes.len() as u64) }
    }

    /// Runs up to `cycles` clocks, storing GMII bytes into the buffers (equal lengths);
    /// returns (cycles run, bytes stored, tx_er clocks).
    pub(crate) fn run(
        &mut self,
        library: &Library,
        cycles: u64,
        offsets: &mut [u32],
        bytes: &mut [u8],
    ) -> (u64, usize, u64) {
        let capacity = offsets.len().min(bytes.len()) as u64;
        let (mut stored, mut errors) = (0u64, 0u64);
        // SAFETY: valid handle; both buffers hold `capacity` elements; the shim writes at
        // most `capacity` of each.
        let run = unsafe {
            (library.run)(
                self.handle,
                cycles,
                offsets.as_mut_ptr(),
                bytes.as_mut_ptr(),
                capacity,
                &mut stored,
                &mut errors,
            )
        };
        (run, stored as usize, errors)
    }

    /// Moves up to the buffers' length of the UART transmit pin changes recorded so far
    /// (rising edge, port, new level), oldest first, into the buffers; returns how many.
    pub(crate) fn take_tx(
        &mut self,
        library: &Library,
        edges: &mut [u64],
        ports: &mut [u32],
        levels: &mut [u8],
    ) -> usize {
        let capacity = edges.len().min(ports.len()).min(levels.len()) as u64;
        // SAFETY: valid handle; the three buffers hold `capacity` elements each; the shim
        // writes at most `capacity` of each.
        let n = unsafe {
            (library.take_tx)(
                self.handle,
                edges.as_mut_ptr(),
                ports.as_mut_ptr(),
                levels.as_mut_ptr(),
                capacity,
            )
        };
        n as usize
    }

    pub(crate) fn free(&mut self, library: &Library) {
        if !self.handle.is_null() {
            // SAFETY: valid handle, freed once (set to null after).
            unsafe { (library.free)(self.handle) };
            self.handle = std::ptr::null_mut();
        }
    }
}
