//! The inner loops of the dynamic factor, over *runs*: maximal stretches of
//! a column whose rows are consecutive.
//!
//! Near the root of the elimination tree a column of a pose-graph factor is
//! nearly dense (City10000: 91% of the entries an update walks sit in runs
//! of 8 rows or more), so a run's rows address a contiguous slice of any
//! dense vector, and the loop over it vectorises. Each function here does
//! the per-row loop's arithmetic, in the same order per row, so the results
//! are the same up to rounding.

use crate::sparse::Scalar;

// the kernels below are written for at most this many vectors
const _: () = assert!(super::scratch::MAX_RANK == 12);

/// `$fixed::<K>(w, args)` for `K` = `w.len()` vectors from 1 to
/// `MAX_RANK`, else `$generic(w, args)`.
macro_rules! by_rank {
    ($fixed:ident, $generic:ident, $w:ident, $($arg:ident),*) => {
        match $w.len() {
            1 => $fixed::<1>($w, $($arg),*),
            2 => $fixed::<2>($w, $($arg),*),
            3 => $fixed::<3>($w, $($arg),*),
            4 => $fixed::<4>($w, $($arg),*),
            5 => $fixed::<5>($w, $($arg),*),
            6 => $fixed::<6>($w, $($arg),*),
            7 => $fixed::<7>($w, $($arg),*),
            8 => $fixed::<8>($w, $($arg),*),
            9 => $fixed::<9>($w, $($arg),*),
            10 => $fixed::<10>($w, $($arg),*),
            11 => $fixed::<11>($w, $($arg),*),
            12 => $fixed::<12>($w, $($arg),*),
            _ => $generic($w, $($arg),*),
        }
    };
}

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

/// One column step of a multiple-rank update over every run of a column
/// (its `rows`, their [`run_starts`] and values `l`): for every element and
/// each vector `t` in turn, `w_t ← w_t − p_t l`, then `l ← l + g_t w_t`. All
/// vectors go in one pass, so that `l` is loaded and stored once however
/// many there are.
#[inline]
pub(crate) fn rank_runs_generic<T: Scalar>(
    w: &mut [&mut [T]],
    (rows, starts): (&[u32], &[u32]),
    l: &mut [T],
    p: &[T],
    g: &[T],
) {
    for_each_run(rows, starts, |first, at| {
        for (e, lv) in l[at].iter_mut().enumerate() {
            row_step(w, first + e, lv, p, g);
        }
    });
}

/// The step of every vector at row `r` of a column whose value there is
/// `l`: for each `t` in turn, `w_t ← w_t − p_t l`, then `l ← l + g_t w_t`.
#[inline(always)]
fn row_step<T: Scalar>(w: &mut [&mut [T]], r: usize, l: &mut T, p: &[T], g: &[T]) {
    let mut x = *l;
    for (t, w) in w.iter_mut().enumerate() {
        let a = w[r] - p[t] * x;
        w[r] = a;
        x += g[t] * a;
    }
    *l = x;
}

/// [`rank_runs_generic`] for exactly `K` vectors, with fused multiply-adds:
/// the vectors unroll, and the loop over a run's rows vectorises. The
/// number of vectors is dispatched once per column, not per run: a short
/// run (a keyframe's three rows) costs its arithmetic, not a call.
#[inline(always)]
fn rank_runs_fixed<const K: usize>(
    w: &mut [&mut [f64]],
    (rows, starts): (&[u32], &[u32]),
    l: &mut [f64],
    p: &[f64],
    g: &[f64],
) {
    let Some((ws, _)) = w.split_first_chunk_mut::<K>() else {
        unreachable!("K = w.len() vectors");
    };
    let np: [f64; K] = std::array::from_fn(|t| -p[t]);
    let g: [f64; K] = std::array::from_fn(|t| g[t]);
    for_each_run(rows, starts, |first, at| {
        let l = &mut l[at];
        let n = l.len();
        let ws: [&mut [f64]; K] = ws.each_mut().map(|s| &mut s[first..first + n]);
        for e in 0..n {
            let mut x = l[e];
            for t in 0..K {
                let a = np[t].mul_add(x, ws[t][e]);
                x = g[t].mul_add(a, x);
                ws[t][e] = a;
            }
            l[e] = x;
        }
    });
}

/// [`rank_runs_generic`] compiled for AVX2 with fused multiply-adds (four
/// lanes; each step rounds once instead of twice), for up to `MAX_RANK`
/// vectors.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn rank_runs_fma(
    w: &mut [&mut [f64]],
    runs: (&[u32], &[u32]),
    l: &mut [f64],
    p: &[f64],
    g: &[f64],
) {
    by_rank!(rank_runs_fixed, rank_runs_generic, w, runs, l, p, g)
}

/// One column step of a multiple-rank update over a column whose runs are
/// short: [`rank_runs_generic`]'s arithmetic, row by row at the given `rows`.
#[inline]
pub(crate) fn rank_rows_generic<T: Scalar>(w: &mut [&mut [T]], rows: &[u32], l: &mut [T], p: &[T], g: &[T]) {
    for (&r, lv) in rows.iter().zip(l.iter_mut()) {
        row_step(w, r as usize, lv, p, g);
    }
}

/// [`rank_rows_generic`] for exactly `K` vectors, with fused
/// multiply-adds: the vectors unroll and one bounds check covers them all.
#[inline(always)]
fn rank_rows_fixed<const K: usize>(w: &mut [&mut [f64]], rows: &[u32], l: &mut [f64], p: &[f64], g: &[f64]) {
    // the vectors are distinct already; a short column cannot afford
    // checking so again (`get_disjoint_mut`)
    let Some((ws, _)) = w.split_first_chunk_mut::<K>() else {
        unreachable!("K = w.len() vectors");
    };
    let n = ws[0].len();
    let ws: [&mut [f64]; K] = ws.each_mut().map(|s| &mut s[..n]);
    let np: [f64; K] = std::array::from_fn(|t| -p[t]);
    let g: [f64; K] = std::array::from_fn(|t| g[t]);
    for (&r, lv) in rows.iter().zip(l.iter_mut()) {
        let r = r as usize;
        assert!(r < n, "row {r} past the accumulators");
        let mut x = *lv;
        for t in 0..K {
            let a = np[t].mul_add(x, ws[t][r]);
            ws[t][r] = a;
            x = g[t].mul_add(a, x);
        }
        *lv = x;
    }
}

/// [`rank_rows_generic`] compiled with fused multiply-adds, for up to
/// `MAX_RANK` vectors.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn rank_rows_fma(w: &mut [&mut [f64]], rows: &[u32], l: &mut [f64], p: &[f64], g: &[f64]) {
    by_rank!(rank_rows_fixed, rank_rows_generic, w, rows, l, p, g)
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

/// [`gather_dot`] for reals with fused multiply-adds, in four running
/// sums taken row by row across the runs. A column's runs are short (eight
/// rows on average once [`dense_enough`]): summing run by run would leave
/// most of each column to one serial chain and set a loop up per run,
/// while with `x` in cache the gather costs less (the solve 7–20% faster
/// in the `incremental_path` bench). Sums in another order than
/// [`gather_dot`], so the last bits differ.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn gather_dot_fma(x: &[f64], (rows, vals, _): (&[u32], &[f64], &[u32])) -> f64 {
    let mut s = [0.0f64; 4];
    let mut rc = rows.chunks_exact(4);
    let mut vc = vals.chunks_exact(4);
    for (r4, l4) in (&mut rc).zip(&mut vc) {
        for k in 0..4 {
            s[k] = x[r4[k] as usize].mul_add(l4[k], s[k]);
        }
    }
    for (&r, &l) in rc.remainder().iter().zip(vc.remainder()) {
        s[0] = x[r as usize].mul_add(l, s[0]);
    }
    (s[0] + s[1]) + (s[2] + s[3])
}
