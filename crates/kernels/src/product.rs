//! The one shape in which the kernels call the `gemm` crate: `dst (+)= lhs ·
//! rhs` on matrices given as a pointer and two strides, so that the
//! convolutions' products read and write NCHW tensors, tiles and their
//! transposes in place, without a layout copy.

// A thin wrapper over gemm's pointer interface; the callers check every
// extent against their slices and state why in their SAFETY comments.
#![allow(unsafe_code)]

/// A matrix in memory: its first element and the distance, in elements,
/// from one column to the next (`col`) and from one row to the next (`row`).
#[derive(Clone, Copy)]
pub(crate) struct View<P> {
    ptr: P,
    col: isize,
    row: isize,
}

/// Rows `row` elements apart, each contiguous (a row-major block).
pub(crate) fn row_major<P>(ptr: P, row: usize) -> View<P> {
    View {
        ptr,
        col: 1,
        row: row as isize,
    }
}

/// The transpose of a row-major block whose rows are `col` apart: element
/// (r, c) at `ptr + c * col + r`.
pub(crate) fn transposed<P>(ptr: P, col: usize) -> View<P> {
    View {
        ptr,
        col: col as isize,
        row: 1,
    }
}

/// `dst = lhs · rhs`, or `dst += lhs · rhs` when `accumulate`: `dst` is `m x
/// n`, `lhs` `m x k`, `rhs` `k x n`, with gemm's parallelism `par` inside.
///
/// # Safety
/// Every element the three views address for these sizes must lie inside
/// its buffer; `dst`'s must be writable and touched by no other thread
/// during the call.
pub(crate) unsafe fn product(
    (m, n, k): (usize, usize, usize),
    dst: View<*mut f32>,
    accumulate: bool,
    lhs: View<*const f32>,
    rhs: View<*const f32>,
    par: gemm::Parallelism,
) {
    // SAFETY: the caller's contract.
    unsafe {
        gemm::gemm(
            m, n, k, dst.ptr, dst.col, dst.row, accumulate, lhs.ptr, lhs.col, lhs.row, rhs.ptr,
            rhs.col, rhs.row, 1.0, 1.0, false, false, false, par,
        );
    }
}
