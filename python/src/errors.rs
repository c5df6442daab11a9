//! The package's exceptions, and Rust errors as them (each with the reason the Rust side
//! gives).

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::PyErr;
use skinbox_host::pcap::PcapError;

create_exception!(
    _native,
    SkinboxError,
    PyException,
    "Base class of the errors skinbox raises."
);
create_exception!(
    _native,
    CaptureFileError,
    SkinboxError,
    "A file that is no pcap or pcapng this reader takes (the reason says why)."
);
create_exception!(
    _native,
    BadInputError,
    SkinboxError,
    "A capture with bad input: frames, datagrams or records the decoder rejected, by reason."
);
create_exception!(
    _native,
    BoxError,
    SkinboxError,
    "A box did not acknowledge a command, or its socket failed."
);
create_exception!(
    _native,
    BoxRefusedError,
    BoxError,
    "A box acknowledged a command and refused it; the message names the reason."
);
create_exception!(
    _native,
    EmulatorError,
    SkinboxError,
    "An emulated box could not be started or stopped with an error."
);
create_exception!(
    _native,
    CaptureError,
    SkinboxError,
    "A live capture could not start or stopped with an error."
);

/// A `ValueError` with `message`.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// A pcap error as the exception a Python caller expects: a missing file is
/// `FileNotFoundError`, another I/O failure `OSError`, anything else `CaptureFileError`.
pub fn pcap_error(e: PcapError) -> PyErr {
    match &e {
        PcapError::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        PcapError::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => CaptureFileError::new_err(e.to_string()),
    }
}
