//! The numpy dtypes of the rows of `skinbox_host::rows`, built from their field lists, and
//! the rows as numpy elements.

use numpy::{Element, PyArrayDescr};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyList};
use skinbox_host::rows::{RecordRow, RowField, SampleRow, RECORD_FIELDS, SAMPLE_FIELDS};

/// A [`RecordRow`] as a numpy element (the same bytes).
#[repr(transparent)]
#[derive(Clone, Copy, Default)]
pub struct RecordElement(pub RecordRow);

/// A [`SampleRow`] as a numpy element (the same bytes).
#[repr(transparent)]
#[derive(Clone, Copy, Default)]
pub struct SampleElement(pub SampleRow);

static RECORD_DTYPE: PyOnceLock<Py<PyArrayDescr>> = PyOnceLock::new();
static SAMPLE_DTYPE: PyOnceLock<Py<PyArrayDescr>> = PyOnceLock::new();

/// A structured dtype of `fields` with the row's size.
fn dtype<'py>(
    py: Python<'py>,
    fields: &[RowField],
    itemsize: usize,
) -> PyResult<Bound<'py, PyArrayDescr>> {
    let spec = PyDict::new(py);
    spec.set_item("names", PyList::new(py, fields.iter().map(|f| f.0))?)?;
    spec.set_item("formats", PyList::new(py, fields.iter().map(|f| f.1))?)?;
    spec.set_item("offsets", PyList::new(py, fields.iter().map(|f| f.2))?)?;
    spec.set_item("itemsize", itemsize)?;
    PyArrayDescr::new(py, &spec)
}

/// The dtype of record rows.
pub fn record_dtype(py: Python<'_>) -> PyResult<Bound<'_, PyArrayDescr>> {
    RECORD_DTYPE
        .get_or_try_init(py, || {
            dtype(py, RECORD_FIELDS, std::mem::size_of::<RecordRow>()).map(Bound::unbind)
        })
        .map(|d| d.bind(py).clone())
}

/// The dtype of sample rows.
pub fn sample_dtype(py: Python<'_>) -> PyResult<Bound<'_, PyArrayDescr>> {
    SAMPLE_DTYPE
        .get_or_try_init(py, || {
            dtype(py, SAMPLE_FIELDS, std::mem::size_of::<SampleRow>()).map(Bound::unbind)
        })
        .map(|d| d.bind(py).clone())
}

// SAFETY: the rows are plain old data (integers and floats, no pointers), and the dtype
// describes their `repr(C)` layout: every field at its `offset_of!`, the row's size as
// itemsize (checked against the fields by skinbox-host's tests). The module builds both
// dtypes when it is imported, so `get_dtype` finds them built.
unsafe impl Element for RecordElement {
    const IS_COPY: bool = true;

    fn get_dtype(py: Python<'_>) -> Bound<'_, PyArrayDescr> {
        record_dtype(py).expect("the record dtype is built when the module is imported")
    }

    fn clone_ref(&self, _py: Python<'_>) -> Self {
        *self
    }
}

// SAFETY: as for `RecordElement`.
unsafe impl Element for SampleElement {
    const IS_COPY: bool = true;

    fn get_dtype(py: Python<'_>) -> Bound<'_, PyArrayDescr> {
        sample_dtype(py).expect("the sample dtype is built when the module is imported")
    }

    fn clone_ref(&self, _py: Python<'_>) -> Self {
        *self
    }
}

/// Record rows as numpy elements, without copying: the element is the row.
pub fn as_record_rows(elements: &mut [RecordElement]) -> &mut [RecordRow] {
    // SAFETY: RecordElement is repr(transparent) over RecordRow.
    unsafe { std::slice::from_raw_parts_mut(elements.as_mut_ptr().cast(), elements.len()) }
}

/// Sample rows as numpy elements, without copying.
pub fn as_sample_rows(elements: &mut [SampleElement]) -> &mut [SampleRow] {
    // SAFETY: SampleElement is repr(transparent) over SampleRow.
    unsafe { std::slice::from_raw_parts_mut(elements.as_mut_ptr().cast(), elements.len()) }
}
