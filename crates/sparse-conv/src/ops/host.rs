//! How the ops' CPU paths reach a CPU backend's values: read a tensor's floats without a copy
//! when it is contiguous, and wrap the values a kernel returns in a tensor again, for f32 and f64.

// burn-ndarray is deprecated in Burn 0.22 but is one of the CPU backends pmunet supports.
#![allow(deprecated)]

use std::borrow::Cow;

use burn::backend::ndarray::NdArrayTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Flex, NdArray, TensorMetadata};

use crate::kernels::cpu::Element;

/// Read access to a CPU backend's float values, without a copy when the tensor is contiguous
/// (reading through `into_data` copies every tensor autodiff also holds, element by element on
/// ndarray). Every op implements its backend trait once for all backends with this trait, on
/// the CPU kernels; a new host backend needs only an impl here.
pub(crate) trait HostFloats: Backend {
    /// The f32 values, row-major.
    fn host_f32(t: &FloatTensor<Self>) -> Cow<'_, [f32]>;
    /// The f64 values, row-major.
    fn host_f64(t: &FloatTensor<Self>) -> Cow<'_, [f64]>;
}

impl HostFloats for Flex {
    fn host_f32(t: &FloatTensor<Self>) -> Cow<'_, [f32]> {
        // A strided view (e.g. the broadcast seed of a `sum` backward) is laid out once, and
        // its buffer taken over rather than copied again.
        t.as_slice::<f32>().map_or_else(|| Cow::Owned(t.to_contiguous().into_data().into_vec::<f32>().expect("an f32 tensor")), Cow::Borrowed)
    }
    fn host_f64(t: &FloatTensor<Self>) -> Cow<'_, [f64]> {
        t.as_slice::<f64>().map_or_else(|| Cow::Owned(t.to_contiguous().into_data().into_vec::<f64>().expect("an f64 tensor")), Cow::Borrowed)
    }
}

impl HostFloats for NdArray {
    fn host_f32(t: &FloatTensor<Self>) -> Cow<'_, [f32]> {
        match t {
            NdArrayTensor::F32(s) => match s.view().to_slice() {
                Some(v) => Cow::Borrowed(v),
                None => {
                    let v = s.view();
                    // SAFETY: the pointer, shape and strides are the live view's.
                    Cow::Owned(unsafe { strided_2d(v.as_ptr(), v.shape(), v.strides()) }.unwrap_or_else(|| v.iter().copied().collect()))
                }
            },
            other => panic!("expected an f32 tensor, got {:?}", other.dtype()),
        }
    }
    fn host_f64(t: &FloatTensor<Self>) -> Cow<'_, [f64]> {
        match t {
            NdArrayTensor::F64(s) => match s.view().to_slice() {
                Some(v) => Cow::Borrowed(v),
                None => {
                    let v = s.view();
                    // SAFETY: as in `host_f32`.
                    Cow::Owned(unsafe { strided_2d(v.as_ptr(), v.shape(), v.strides()) }.unwrap_or_else(|| v.iter().copied().collect()))
                }
            },
            other => panic!("expected an f64 tensor, got {:?}", other.dtype()),
        }
    }
}

/// A strided `[rows, C]` view's values in row-major order, row by row (`None` for other ranks).
/// ndarray's own iterator over a dynamic-rank view indexes element by element; the views that
/// reach the op are 2-D (a gradient seed broadcast from a `sum`, a column slice).
///
/// # Safety
/// `ptr`, `shape` and `strides` (in elements) must describe a valid view.
unsafe fn strided_2d<T: Copy>(ptr: *const T, shape: &[usize], strides: &[isize]) -> Option<Vec<T>> {
    let (&[rows, c], &[rs, cs]) = (shape, strides) else { return None };
    let mut out = Vec::with_capacity(rows * c);
    for i in 0..rows {
        // SAFETY: (i, j) lies inside the view for i < rows, j < c.
        let row = unsafe { ptr.offset(i as isize * rs) };
        if cs == 1 {
            out.extend_from_slice(unsafe { std::slice::from_raw_parts(row, c) });
        } else {
            out.extend((0..c).map(|j| unsafe { *row.offset(j as isize * cs) }));
        }
    }
    Some(out)
}

/// An element type of the CPU kernels, read from a CPU backend's tensor.
pub(crate) trait Host: Element {
    /// The values of `t`, row-major.
    fn host<B: HostFloats>(t: &FloatTensor<B>) -> Cow<'_, [Self]>;
}

impl Host for f32 {
    fn host<B: HostFloats>(t: &FloatTensor<B>) -> Cow<'_, [f32]> {
        B::host_f32(t)
    }
}

impl Host for f64 {
    fn host<B: HostFloats>(t: &FloatTensor<B>) -> Cow<'_, [f64]> {
        B::host_f64(t)
    }
}

/// Evaluates `$body` with `$T` the element type (f32 or f64) the tensors share, and wraps the
/// values it returns, of shape `$shape`, in a `$B` tensor on the first tensor's device.
macro_rules! on_host {
    ($B:ty, [$first:expr $(, $other:expr)* $(,)?], $shape:expr, |$T:ident| $body:expr) => {{
        let dtype = $first.dtype();
        $(assert_eq!($other.dtype(), dtype, "the op's tensors must share a dtype, got {:?} and {dtype:?}", $other.dtype());)*
        let device = $first.device();
        let data = match dtype {
            burn::tensor::DType::F32 => {
                type $T = f32;
                burn::tensor::TensorData::new($body, $shape)
            }
            burn::tensor::DType::F64 => {
                type $T = f64;
                burn::tensor::TensorData::new($body, $shape)
            }
            other => panic!("the CPU kernels run on f32 and f64 tensors, got {other:?}"),
        };
        <$B as burn::backend::ops::FloatTensorOps<$B>>::float_from_data(data, &device)
    }};
}
pub(crate) use on_host;
