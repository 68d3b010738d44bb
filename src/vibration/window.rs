//! Online estimate of the vibration from the compensated samples, for systems that sample
//! fast enough to see it: the moments of each axis (mean, second to fourth central moments,
//! mean absolute value) and the cross covariances over consecutive blocks of `W` samples
//! (a tumbling window: no ring buffer, one accumulation per sample, no allocation).
//!
//! A block's moments are available from the sample that completes it until the next block
//! completes, so an estimate is at most `2W` samples of the window old (the pipeline feeds
//! it one block in four, [`ONLINE_BLOCK_EVERY`](crate::pipeline::ONLINE_BLOCK_EVERY): at most
//! `5W` samples, 320 ms with the firmware's 64 at 1 kHz); flight-phase vibration changes over
//! seconds. A sliding window would
//! give a new estimate on every sample but costs three accumulations per sample (add the
//! new sample, remove the oldest, and a drift-free second set) and `W` stored samples.
//!
//! # Numerics
//!
//! The sums are taken of deviations `d = x − c` from a centre `c`, the previous block's mean,
//! so a large static acceleration (10 g) does not swamp a small vibration (0.01 g) by
//! cancellation in `f32`. Each block's sums start from zero, so rounding errors never
//! accumulate beyond `W` additions, whatever the run length.

use super::{AccelAxes, Axis, VibMoments};
use crate::float::Float;
use crate::linalg::Vec3;

/// Power sums of the deviations from a centre.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sums<F> {
    s1: Vec3<F>,
    s2: Vec3<F>,
    s3: Vec3<F>,
    s4: Vec3<F>,
    /// Σ(|x| − |c|).
    abs: Vec3<F>,
    /// Σ d_x d_y, Σ d_y d_z, Σ d_z d_x.
    cross: Vec3<F>,
}

impl<F: Float> Sums<F> {
    const ZERO: Sums<F> = Sums {
        s1: [F::ZERO; 3],
        s2: [F::ZERO; 3],
        s3: [F::ZERO; 3],
        s4: [F::ZERO; 3],
        abs: [F::ZERO; 3],
        cross: [F::ZERO; 3],
    };

    /// Adds the samples `xs` (at most [`CHUNK`]) under centre `c`, in order, to these sums
    /// or, with `fresh`, to zero sums (the block's first chunk): per sample and
    /// axis the deviation `d = x − c`, `d`, `d²`, `d³`, `d⁴` (the last two by fused
    /// multiply-adds) and `|x| − |c|`, and the three cross products, the sums held in
    /// registers over the samples and stored once. Out of line,
    /// as it runs once per `CHUNK` samples, and not unrolled (unrolled, the sums move between
    /// registers from one sample to the next).
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn add_all(&mut self, xs: &[Vec3<F>], c: &Vec3<F>, fresh: bool) {
        let [cx, cy, cz] = *c;
        let (ax, ay, az) = (cx.abs(), cy.abs(), cz.abs());
        let from = if fresh { Sums::ZERO } else { *self };
        let [mut s1x, mut s1y, mut s1z] = from.s1;
        let [mut s2x, mut s2y, mut s2z] = from.s2;
        let [mut s3x, mut s3y, mut s3z] = from.s3;
        let [mut s4x, mut s4y, mut s4z] = from.s4;
        let [mut sax, mut say, mut saz] = from.abs;
        let [mut cxy, mut cyz, mut czx] = from.cross;
        for &[x, y, z] in xs {
            let (dx, dy, dz) = (x - cx, y - cy, z - cz);
            let (qx, qy, qz) = (dx * dx, dy * dy, dz * dz);
            s1x += dx;
            s1y += dy;
            s1z += dz;
            s2x += qx;
            s2y += qy;
            s2z += qz;
            s3x = qx.mul_add(dx, s3x);
            s3y = qy.mul_add(dy, s3y);
            s3z = qz.mul_add(dz, s3z);
            s4x = qx.mul_add(qx, s4x);
            s4y = qy.mul_add(qy, s4y);
            s4z = qz.mul_add(qz, s4z);
            sax += x.abs() - ax;
            say += y.abs() - ay;
            saz += z.abs() - az;
            cxy = dx.mul_add(dy, cxy);
            cyz = dy.mul_add(dz, cyz);
            czx = dz.mul_add(dx, czx);
        }
        *self = Sums {
            s1: [s1x, s1y, s1z],
            s2: [s2x, s2y, s2z],
            s3: [s3x, s3y, s3z],
            s4: [s4x, s4y, s4z],
            abs: [sax, say, saz],
            cross: [cxy, cyz, czx],
        };
    }
}

/// Moments of one block of `W` samples, per unit axis x, y, z.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WindowMoments<F> {
    /// Window mean \[g\]: the static acceleration `a_p`.
    pub mean_g: Vec3<F>,
    /// Variance `⟨ã²⟩` \[g²\].
    pub var_g2: Vec3<F>,
    /// Third central moment `⟨ã³⟩` \[g³\].
    pub m3_g3: Vec3<F>,
    /// Fourth central moment `⟨ã⁴⟩` \[g⁴\].
    pub m4_g4: Vec3<F>,
    /// Covariances `⟨ã_x ã_y⟩`, `⟨ã_y ã_z⟩`, `⟨ã_z ã_x⟩` \[g²\].
    pub cov_g2: Vec3<F>,
    /// `⟨|a|⟩ − |⟨a⟩|` \[g\]: the rectification of the absolute value that drives the
    /// asymmetry term.
    pub abs_excess_g: Vec3<F>,
}

impl<F: Float> WindowMoments<F> {
    /// The moments seen by accelerometer `axis` (IA central moments, IA·OA and IA·PA
    /// covariances) and its IA `⟨|a3|⟩ − |⟨a3⟩|`.
    pub fn on_accel(&self, axis: Axis) -> (VibMoments<F>, F) {
        let pick = |v: &Vec3<F>| AccelAxes::from_unit(v, axis).ia;
        // cov(IA, OA) and cov(IA, PA) from the cyclic pairs xy, yz, zx.
        let (cov_oa, cov_pa) = match axis {
            Axis::X => (self.cov_g2[2], self.cov_g2[0]),
            Axis::Y => (self.cov_g2[0], self.cov_g2[1]),
            Axis::Z => (self.cov_g2[1], self.cov_g2[2]),
        };
        let m = VibMoments {
            m2_g2: pick(&self.var_g2),
            m3_g3: pick(&self.m3_g3),
            m4_g4: pick(&self.m4_g4),
            cov_oa_g2: cov_oa,
            cov_pa_g2: cov_pa,
        };
        (m, pick(&self.abs_excess_g))
    }

    /// Refers moments of the output back to the acceleration: the output of an axis is
    /// `g·ã` (`g` = that axis's gain, see
    /// [`VibrationConfig::output_gains`](super::VibrationConfig::output_gains)), so moments of
    /// order k are divided by `g^k` and covariances by `g_i g_j`. Gains that are not positive
    /// and finite are ignored.
    pub fn unscale(&mut self, gains: &Vec3<F>) {
        let mut r = [F::ONE; 3];
        for i in 0..3 {
            if gains[i] > F::ZERO && gains[i].is_finite() {
                r[i] = F::ONE / gains[i];
            }
            self.var_g2[i] *= r[i] * r[i];
            self.m3_g3[i] *= r[i] * r[i] * r[i];
            self.m4_g4[i] *= r[i] * r[i] * r[i] * r[i];
            self.abs_excess_g[i] *= r[i];
        }
        self.cov_g2[0] *= r[0] * r[1];
        self.cov_g2[1] *= r[1] * r[2];
        self.cov_g2[2] *= r[2] * r[0];
    }

    /// Limits the vibration to `max_sigma_g` per axis: an axis whose σ exceeds it has its
    /// moments of order k scaled by `s^k` (`s = max/σ`) and its covariances by `s`, which keeps
    /// the shape of the distribution. Returns true when anything was clamped.
    pub fn clamp_sigma(&mut self, max_sigma_g: F) -> bool {
        let mut scale = [F::ONE; 3];
        let mut clamped = false;
        for i in 0..3 {
            let sigma = self.var_g2[i].sqrt();
            if sigma > max_sigma_g {
                clamped = true;
                let s = max_sigma_g / sigma;
                scale[i] = s;
                self.var_g2[i] *= s * s;
                self.m3_g3[i] *= s * s * s;
                self.m4_g4[i] *= s * s * s * s;
                self.abs_excess_g[i] *= s;
            }
        }
        self.cov_g2[0] *= scale[0] * scale[1];
        self.cov_g2[1] *= scale[1] * scale[2];
        self.cov_g2[2] *= scale[2] * scale[0];
        clamped
    }
}

/// What [`MomentWindow::push`] did with a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pushed {
    /// Not finite: ignored.
    Rejected,
    /// Added to the current block.
    Accepted,
    /// Added, and it completed a block: [`MomentWindow::moments`] changed.
    BlockDone,
}

/// Samples of the current block held before they enter its sums: the sums are updated once
/// per `CHUNK` samples (and at the end of a block), so their 18 accumulators are loaded and
/// stored once for `CHUNK` samples instead of once per sample. The same operations in the
/// same order: the sums are the same bits as sample by sample.
pub const CHUNK: usize = 8;

/// Block moment estimator over consecutive blocks of `W` samples (configuration-free state;
/// `W` is the block length in samples). Choose `W` to span many vibration periods: the
/// estimate of a sine's variance over a block of P periods is within about `1/(2πP)` of
/// `a²/2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MomentWindow<F, const W: usize> {
    /// Samples of the current block so far (< W).
    pass: usize,
    /// Centre of the current block's sums.
    c_acc: Vec3<F>,
    /// The sums of two blocks, `sums[cur]` the current block's (over its samples before the
    /// last `pass % CHUNK`, set afresh by its first chunk) and the other the last complete
    /// block's: a completed block's sums change roles, they are not copied.
    sums: [Sums<F>; 2],
    /// Index of the current block's sums (0 or 1).
    cur: usize,
    /// The current block's last `pass % CHUNK` samples, not yet in `acc`.
    pending: [Vec3<F>; CHUNK],
    /// Centre of the last complete block's sums.
    c_done: Vec3<F>,
    /// Blocks completed (saturating).
    blocks: u32,
}

impl<F: Float, const W: usize> Default for MomentWindow<F, W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Float, const W: usize> MomentWindow<F, W> {
    /// An empty window.
    pub const fn new() -> Self {
        MomentWindow {
            pass: 0,
            c_acc: [F::ZERO; 3],
            sums: [Sums::ZERO; 2],
            cur: 0,
            pending: [[F::ZERO; 3]; CHUNK],
            c_done: [F::ZERO; 3],
            blocks: 0,
        }
    }

    /// Empties the window.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// True before the first accepted sample.
    pub fn is_empty(&self) -> bool {
        self.blocks == 0 && self.pass == 0
    }

    /// True once a block of `W` samples has completed (and `W > 0`).
    pub fn is_full(&self) -> bool {
        W > 0 && self.blocks > 0
    }

    /// Blocks completed since the last reset (saturates at `u32::MAX`).
    pub fn blocks(&self) -> u32 {
        self.blocks
    }

    /// Adds one sample \[g\] (x, y, z) to the current block. A sample with a non-finite element
    /// is ignored. O(1), allocation- and panic-free.
    pub fn push(&mut self, x: &Vec3<F>) -> Pushed {
        if !(x[0].is_finite() && x[1].is_finite() && x[2].is_finite()) || W == 0 {
            return Pushed::Rejected;
        }
        self.push_finite(x)
    }

    /// [`push`](Self::push) for a sample the caller knows to be finite (the per-sample step's
    /// compensated output is).
    #[inline]
    pub(crate) fn push_finite(&mut self, x: &Vec3<F>) -> Pushed {
        if W == 0 {
            return Pushed::Rejected;
        }
        let k = self.pass % CHUNK;
        if let Some(slot) = self.pending.get_mut(k) {
            *slot = *x;
        }
        self.pass += 1;
        if k + 1 < CHUNK && self.pass < W {
            return Pushed::Accepted;
        }
        // The block's first chunk: its sums start from zero. The first block is centred on its
        // first sample: set here, where the sums first use the centre, rather than tested on
        // every sample.
        let fresh = self.pass == k + 1;
        if fresh && self.blocks == 0 {
            self.c_acc = self.pending[0];
        }
        let cur = self.cur & 1;
        self.sums[cur].add_all(self.pending.get(..=k).unwrap_or(&[]), &self.c_acc, fresh);
        if self.pass < W {
            return Pushed::Accepted;
        }
        // The block is complete: its sums become the estimate, and the next block is centred
        // on its mean.
        self.c_done = self.c_acc;
        let inv_n = F::ONE / F::from_f64(W as f64);
        let s1 = self.sums[cur].s1;
        for i in 0..3 {
            self.c_acc[i] = self.c_done[i] + s1[i] * inv_n;
        }
        self.cur = cur ^ 1;
        self.pass = 0;
        self.blocks = self.blocks.saturating_add(1);
        Pushed::BlockDone
    }

    /// The moments of the last complete block, or `None` before the first.
    pub fn moments(&self) -> Option<WindowMoments<F>> {
        if !self.is_full() {
            return None;
        }
        let inv_n = F::ONE / F::from_f64(W as f64);
        let s = &self.sums[(self.cur ^ 1) & 1];
        let c = &self.c_done;
        let mut m = WindowMoments::default();
        let mut mu = [F::ZERO; 3];
        for i in 0..3 {
            // Raw moments of d = x − c, then central moments about the mean offset μ.
            let u = s.s1[i] * inv_n;
            let r2 = s.s2[i] * inv_n;
            let r3 = s.s3[i] * inv_n;
            let r4 = s.s4[i] * inv_n;
            let u2 = u * u;
            mu[i] = u;
            let mean = c[i] + u;
            m.mean_g[i] = mean;
            m.var_g2[i] = (r2 - u2).max(F::ZERO);
            m.m3_g3[i] = r3 - F::from_f64(3.0) * u * r2 + F::from_f64(2.0) * u2 * u;
            m.m4_g4[i] =
                (r4 - F::from_f64(4.0) * u * r3 + F::from_f64(6.0) * u2 * r2 - F::from_f64(3.0) * u2 * u2).max(F::ZERO);
            // ⟨|x|⟩ − |mean| = Σ(|x| − |c|)/n + |c| − |mean| ≥ 0 (Jensen).
            m.abs_excess_g[i] = (s.abs[i] * inv_n + (c[i].abs() - mean.abs())).max(F::ZERO);
        }
        m.cov_g2[0] = s.cross[0] * inv_n - mu[0] * mu[1];
        m.cov_g2[1] = s.cross[1] * inv_n - mu[1] * mu[2];
        m.cov_g2[2] = s.cross[2] * inv_n - mu[2] * mu[0];
        Some(m)
    }
}
