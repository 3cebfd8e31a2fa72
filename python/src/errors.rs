//! Errors of the Rust crates as Python exceptions, with the CLI's
//! messages: what a Python user catches is what the error is (a bad
//! argument, a file, memory, an interrupt), never a crash of the
//! interpreter.

use displace_core::Error as CoreError;
use pyo3::exceptions::{
    PyFileNotFoundError, PyKeyboardInterrupt, PyMemoryError, PyOSError, PyPermissionError,
    PyValueError,
};
use pyo3::PyErr;
use std::io::ErrorKind;

/// The exception a core error is: `FileNotFoundError`/`PermissionError`/
/// `OSError` for the file system, `MemoryError` for a refused estimate,
/// `KeyboardInterrupt` for a cancelled job, `ValueError` for the rest (bad
/// values, sizes, names, file contents).
pub fn core(e: CoreError) -> PyErr {
    let message = in_python_terms(&e.to_string());
    match &e {
        CoreError::Io { source, .. } => match source.kind() {
            ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        CoreError::DiskSpace { .. } => PyOSError::new_err(message),
        CoreError::OutOfMemory { .. } | CoreError::TooLarge { .. } => {
            PyMemoryError::new_err(message)
        }
        CoreError::Cancelled => PyKeyboardInterrupt::new_err(message),
        CoreError::Input { .. } if !std::path::Path::new(input_path(&e)).exists() => {
            PyFileNotFoundError::new_err(message)
        }
        _ => PyValueError::new_err(message),
    }
}

/// A message of the core's, its command-line flags named as this
/// package's arguments.
fn in_python_terms(message: &str) -> String {
    message
        .replace("--height-range auto", "height_range=\"auto\"")
        .replace("--height-range", "height_range")
        .replace("--extent", "extent=")
        .replace("--size", "size=")
}

fn input_path(e: &CoreError) -> &std::path::Path {
    match e {
        CoreError::Input { path, .. } => path,
        _ => std::path::Path::new(""),
    }
}

/// The exception a scene or render error is: the core's where it wraps
/// one, `OSError` for files, `KeyboardInterrupt` for a cancelled render,
/// `ValueError` for a scene that cannot be built.
pub fn render(e: displace_render::Error) -> PyErr {
    use displace_render::Error as R;
    match e {
        R::Core(c) => core(c),
        R::Cancelled => PyKeyboardInterrupt::new_err("render cancelled"),
        e => {
            let message = e.to_string();
            match find_io(&e) {
                Some(ErrorKind::NotFound) => PyFileNotFoundError::new_err(message),
                Some(ErrorKind::PermissionDenied) => PyPermissionError::new_err(message),
                Some(_) => PyOSError::new_err(message),
                None => PyValueError::new_err(message),
            }
        }
    }
}

/// The kind of the I/O error under `e`, if any (a scene file that is not
/// there, a texture it names that cannot be read).
fn find_io(e: &(dyn std::error::Error + 'static)) -> Option<ErrorKind> {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = cur {
        if let Some(io) = err.downcast_ref::<std::io::Error>() {
            return Some(io.kind());
        }
        cur = err.source();
    }
    None
}

/// A `ValueError` for a bad argument.
pub fn value(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}
