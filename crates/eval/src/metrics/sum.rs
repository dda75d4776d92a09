//! f64 sums in a fixed order that the compiler can vectorise: four
//! independent lanes instead of one serial chain (a single running `+=` waits
//! for the previous add every element, ~4 cycles each), combined at the end.
//! The order depends only on the length, so results are reproducible.

/// Sum of `f(a[i], b[i])` over two equally long slices.
#[inline(always)]
pub(crate) fn sum2<A: Copy, B: Copy>(a: &[A], b: &[B], f: impl Fn(A, B) -> f64) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let split = n - n % 4;
    let mut lanes = [0.0f64; 4];
    for (ca, cb) in a[..split].chunks_exact(4).zip(b[..split].chunks_exact(4)) {
        for l in 0..4 {
            lanes[l] += f(ca[l], cb[l]);
        }
    }
    let mut total = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
    for (&x, &y) in a[split..].iter().zip(&b[split..]) {
        total += f(x, y);
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_every_element_once() {
        for n in [0, 1, 3, 4, 5, 17] {
            let a: Vec<f64> = (0..n).map(|i| i as f64).collect();
            let b = vec![2.0f64; n];
            let want: f64 = a.iter().map(|v| v * 2.0).sum();
            assert_eq!(sum2(&a, &b, |x, y| x * y), want, "n = {n}");
        }
    }
}
