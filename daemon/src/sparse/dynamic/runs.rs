//! The inner loops of the dynamic factor, over *runs*: maximal stretches of
//! a column whose rows are consecutive.
//!
//! Near the root of the elimination tree a column of a pose-graph factor is
//! nearly dense (City10000: 91% of the entries an update walks sit in runs
//! of 8 rows or more), so a run's rows address a contiguous slice of any
//! dense vector, and the loop over it vectorises. Each function here does
//! what the per-row loop did, in the same order per row, so the results are
//! the same up to rounding.

use crate::sparse::Scalar;

/// Where each run of consecutive rows starts in the sorted `rows`.
pub(crate) fn run_starts(rows: &[u32], starts: &mut Vec<u32>) {
    starts.clear();
    extend_run_starts(rows, 0, starts);
}

/// [`run_starts`] after rows were appended to a column that had `old`
/// rows and whose `starts` covered them.
pub(crate) fn extend_run_starts(rows: &[u32], old: usize, starts: &mut Vec<u32>) {
    for k in old..rows.len() {
        if k == 0 || rows[k] != rows[k - 1] + 1 {
            starts.push(k as u32);
        }
    }
}

/// Whether a column's runs are long enough (8 rows on average) for the
/// loops over runs to beat one pass over its rows.
#[inline]
pub(crate) fn dense_enough(rows: &[u32], starts: &[u32]) -> bool {
    starts.len() * 8 <= rows.len()
}

/// Calls `f(first_row, positions)` for each run of a column, given its
/// rows and [`run_starts`]; `positions` indexes the rows and values.
#[inline]
pub(crate) fn for_each_run(rows: &[u32], starts: &[u32], mut f: impl FnMut(usize, std::ops::Range<usize>)) {
    for (k, &a) in starts.iter().enumerate() {
        let b = starts.get(k + 1).map_or(rows.len(), |&b| b as usize);
        f(rows[a as usize] as usize, a as usize..b);
    }
}

/// One column step of a multiple-rank update over a run of rows starting
/// at `first`: for each vector `t` in turn and every element,
/// `w_t ← w_t − p_t l`, then `l ← l + g_t w_t`. Takes the vectors three at
/// a time, so that `l` is loaded and stored once per three.
#[inline]
pub(crate) fn rank_step<T: Scalar>(w: &mut [&mut [T]], first: usize, l: &mut [T], p: &[T], g: &[T]) {
    let rows = first..first + l.len();
    let mut t = 0;
    while t < w.len() {
        match &mut w[t..] {
            [w0, w1, w2, ..] => {
                let w3 = [
                    &mut w0[rows.clone()],
                    &mut w1[rows.clone()],
                    &mut w2[rows.clone()],
                ];
                T::rank3_run(w3, l, &p[t..t + 3], &g[t..t + 3]);
            }
            [w0, w1] => {
                rank1_run(&mut w0[rows.clone()], l, p[t], g[t]);
                rank1_run(&mut w1[rows.clone()], l, p[t + 1], g[t + 1]);
            }
            [w0] => rank1_run(&mut w0[rows.clone()], l, p[t], g[t]),
            [] => unreachable!(),
        }
        t += 3;
    }
}

#[inline(always)]
fn rank1_run<T: Scalar>(w: &mut [T], l: &mut [T], p: T, g: T) {
    for (w, l) in w.iter_mut().zip(l.iter_mut()) {
        let wi = *w - p * *l;
        *w = wi;
        *l += g * wi;
    }
}

/// Three vectors of [`rank_step`] in one pass over `l`.
#[inline(always)]
pub(crate) fn rank3_run_generic<T: Scalar>(w: [&mut [T]; 3], l: &mut [T], p: &[T], g: &[T]) {
    let [w0, w1, w2] = w;
    let (p0, p1, p2, g0, g1, g2) = (p[0], p[1], p[2], g[0], g[1], g[2]);
    let n = l.len();
    let (w0, w1, w2) = (&mut w0[..n], &mut w1[..n], &mut w2[..n]);
    for e in 0..n {
        let lv = l[e];
        let a = w0[e] - p0 * lv;
        let lv = lv + g0 * a;
        let b = w1[e] - p1 * lv;
        let lv = lv + g1 * b;
        let c = w2[e] - p2 * lv;
        l[e] = lv + g2 * c;
        w0[e] = a;
        w1[e] = b;
        w2[e] = c;
    }
}

/// [`rank3_run_generic`] compiled for AVX2 with fused multiply-adds (four
/// lanes; each step rounds once instead of twice).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn rank3_run_fma(w: [&mut [f64]; 3], l: &mut [f64], p: &[f64], g: &[f64]) {
    let [w0, w1, w2] = w;
    let (p0, p1, p2, g0, g1, g2) = (-p[0], -p[1], -p[2], g[0], g[1], g[2]);
    let n = l.len();
    let (w0, w1, w2) = (&mut w0[..n], &mut w1[..n], &mut w2[..n]);
    for e in 0..n {
        let lv = l[e];
        let a = p0.mul_add(lv, w0[e]);
        let lv = g0.mul_add(a, lv);
        let b = p1.mul_add(lv, w1[e]);
        let lv = g1.mul_add(b, lv);
        let c = p2.mul_add(lv, w2[e]);
        l[e] = g2.mul_add(c, lv);
        w0[e] = a;
        w1[e] = b;
        w2[e] = c;
    }
}

/// `c_r += y L_rj` over the rows of column `j`, by runs.
#[inline]
pub(crate) fn scatter_add<M: Scalar, V: Scalar + std::ops::Mul<M, Output = V>>(
    c: &mut [V],
    (rows, vals, starts): (&[u32], &[M], &[u32]),
    y: V,
) {
    if !dense_enough(rows, starts) {
        for (&r, &l) in rows.iter().zip(vals) {
            c[r as usize] += y * l;
        }
        return;
    }
    for_each_run(rows, starts, |first, at| {
        let c = &mut c[first..first + at.len()];
        for (c, &l) in c.iter_mut().zip(&vals[at]) {
            *c += y * l;
        }
    });
}

/// `Σ_r x_r conj(L_rj)` over the rows of a column, by runs, in four
/// running sums.
#[inline]
pub(crate) fn gather_dot<M: Scalar, V: Scalar + std::ops::Mul<M, Output = V>>(
    x: &[V],
    (rows, vals, starts): (&[u32], &[M], &[u32]),
) -> V {
    if !dense_enough(rows, starts) {
        return rows
            .iter()
            .zip(vals)
            .fold(V::default(), |s, (&r, &l)| s + x[r as usize] * l.conjugate());
    }
    let mut s = [V::default(); 4];
    for_each_run(rows, starts, |first, at| {
        let x = &x[first..first + at.len()];
        let l = &vals[at];
        let mut xc = x.chunks_exact(4);
        let mut lc = l.chunks_exact(4);
        for (x4, l4) in (&mut xc).zip(&mut lc) {
            for k in 0..4 {
                s[k] += x4[k] * l4[k].conjugate();
            }
        }
        for (&x, &l) in xc.remainder().iter().zip(lc.remainder()) {
            s[0] += x * l.conjugate();
        }
    });
    (s[0] + s[1]) + (s[2] + s[3])
}
