//! What the rigs do to the unit over time: a timeline of segments (holds, moves between
//! positions, commanded acceleration ramps), each with its vibration and an optional new
//! chamber set point (reached at the timeline's rate or its own), and the unit's power cycles,
//! built from the tilter's test positions TP1–TP6, the check positions
//! CP1–CP6, the shake table's ten-position plan, flight segments, and placements by hand
//! (random orientations without a reference; tilter positions that are not level).

use bins_comp::ident::{TILTER_POSITIONS_G, check_positions_g};
use bins_comp::vibration::shake::ten_position_plan;
use bins_comp::vibration::{AccelAxes, Axis, Vibration};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Two unit vectors perpendicular to `l` and to each other.
fn perpendiculars(l: &[f64; 3]) -> ([f64; 3], [f64; 3]) {
    let n = norm(l);
    let l = l.map(|x| x / n);
    let k = if l[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let d = l[0] * k[0] + l[1] * k[1] + l[2] * k[2];
    let e1: [f64; 3] = std::array::from_fn(|i| k[i] - d * l[i]);
    let e1 = e1.map(|x| x / norm(&e1));
    let e2 = [l[1] * e1[2] - l[2] * e1[1], l[2] * e1[0] - l[0] * e1[2], l[0] * e1[1] - l[1] * e1[0]];
    (e1, e2)
}

/// How the static specific force moves during a segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// Held at `f_g`: the reference is known.
    Hold([f64; 3]),
    /// The rig turns the unit from one position to the next: the reference is not known
    /// (empty cells), the force rotates from `from` to `to`.
    Move {
        /// Start \[g\].
        from: [f64; 3],
        /// End \[g\].
        to: [f64; 3],
    },
    /// A commanded change of acceleration (flight): known, linear from `from` to `to`.
    Ramp {
        /// Start \[g\].
        from: [f64; 3],
        /// End \[g\].
        to: [f64; 3],
    },
}

/// What the rig writes in the reference cells while it holds the unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Written {
    /// The true specific force (tilter, shake table, flight ramp).
    Truth,
    /// Nothing: the orientation is not measured (the unit placed by hand).
    Nothing,
    /// The label's nominal force, not the true one: a hold placed against its label but not
    /// level.
    Nominal([f64; 3]),
}

/// One piece of the timeline.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// Duration \[s\].
    pub duration_s: f64,
    /// A new chamber set point from the start of this segment [°C].
    pub chamber_c: Option<f64>,
    /// The rate of the move to `chamber_c` [°C/s] (`None`: the thermal model's).
    pub chamber_rate_c_per_s: Option<f64>,
    /// Whether the unit is on (false: no row is written, the die is not heated).
    pub powered: bool,
    /// The static specific force.
    pub motion: Motion,
    /// The vibration applied (reference cells say so when the reference is known).
    pub vib: Vibration<f64>,
    /// The position label (`pos`).
    pub label: Option<String>,
    /// What the reference cells say while the rig state is known.
    pub written: Written,
}

impl Segment {
    /// The static specific force \[g\] at fraction `s` ∈ [0, 1] of the segment.
    pub fn f_at(&self, s: f64) -> [f64; 3] {
        match self.motion {
            Motion::Hold(f) => f,
            Motion::Ramp { from, to } => std::array::from_fn(|i| from[i] + s * (to[i] - from[i])),
            Motion::Move { from, to } => rotate_between(&from, &to, s),
        }
    }

    /// Whether the rig state is known during this segment.
    pub fn reference_known(&self) -> bool {
        !matches!(self.motion, Motion::Move { .. }) && self.written != Written::Nothing
    }

    /// The reference written at fraction `s` (the true force unless [`Written::Nominal`]).
    pub fn written_f_at(&self, s: f64) -> [f64; 3] {
        match self.written {
            Written::Nominal(f) => f,
            _ => self.f_at(s),
        }
    }
}

fn norm(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// A smooth turn from `a` to `b`: the direction interpolated on the great circle (through a
/// perpendicular when they are opposite), the magnitude linearly.
fn rotate_between(a: &[f64; 3], b: &[f64; 3], s: f64) -> [f64; 3] {
    let (na, nb) = (norm(a), norm(b));
    if na == 0.0 || nb == 0.0 {
        return std::array::from_fn(|i| a[i] + s * (b[i] - a[i]));
    }
    let ua = a.map(|x| x / na);
    let ub = b.map(|x| x / nb);
    let cos = (ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2]).clamp(-1.0, 1.0);
    let mag = na + s * (nb - na);
    // Orthonormal partner of ua in the plane of the turn.
    let mut p: [f64; 3] = std::array::from_fn(|i| ub[i] - cos * ua[i]);
    let pn = norm(&p);
    if pn < 1e-9 {
        if cos > 0.0 {
            return ua.map(|x| x * mag);
        }
        // Opposite: turn through any perpendicular axis.
        let k = if ua[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
        let d = ua[0] * k[0] + ua[1] * k[1] + ua[2] * k[2];
        p = std::array::from_fn(|i| k[i] - d * ua[i]);
    }
    let pn = norm(&p);
    let angle = cos.acos() * s;
    std::array::from_fn(|i| mag * (ua[i] * angle.cos() + p[i] / pn * angle.sin()))
}

/// The unit-frame vector whose projections on accelerometer `axis`'s IA, PA, OA are `a`
/// (the inverse of [`AccelAxes::from_unit`]).
pub fn to_unit(a: AccelAxes<f64>, axis: Axis) -> [f64; 3] {
    match axis {
        Axis::X => [a.ia, a.pa, a.oa],
        Axis::Y => [a.oa, a.ia, a.pa],
        Axis::Z => [a.pa, a.oa, a.ia],
    }
}

/// Builds a timeline, keeping track of where the unit is.
#[derive(Clone, Debug)]
pub struct Timeline {
    /// The segments so far.
    pub segments: Vec<Segment>,
    current_f: [f64; 3],
    pending_chamber: Option<(f64, Option<f64>)>,
}

impl Timeline {
    /// An empty timeline with the unit at `start_f_g`.
    pub fn new(start_f_g: [f64; 3]) -> Self {
        Timeline { segments: Vec::new(), current_f: start_f_g, pending_chamber: None }
    }

    /// The static specific force at the end so far \[g\].
    pub fn current_f(&self) -> [f64; 3] {
        self.current_f
    }

    /// Total duration \[s\].
    pub fn duration_s(&self) -> f64 {
        self.segments.iter().map(|s| s.duration_s).sum()
    }

    fn push(&mut self, duration_s: f64, motion: Motion, vib: Vibration<f64>, label: Option<String>) {
        if duration_s > 0.0 {
            let (chamber_c, chamber_rate_c_per_s) = self.pending_chamber.take().unzip();
            self.segments.push(Segment {
                duration_s,
                chamber_c,
                chamber_rate_c_per_s: chamber_rate_c_per_s.flatten(),
                powered: true,
                motion,
                vib,
                label,
                written: Written::Truth,
            });
        }
    }

    /// A new chamber set point from the next segment on.
    pub fn set_chamber(&mut self, c: f64) {
        self.pending_chamber = Some((c, None));
    }

    /// A new chamber set point from the next segment on, reached at `rate_c_per_s` [°C/s]
    /// (infinite: jumps) instead of the thermal model's rate.
    pub fn set_chamber_at_rate(&mut self, c: f64, rate_c_per_s: f64) {
        self.pending_chamber = Some((c, Some(rate_c_per_s)));
    }

    /// The unit off for `off_s` where it is (no rows; a pending set point applies from the
    /// turn-off), then on again from the next segment.
    pub fn power_off(&mut self, off_s: f64) {
        let n = self.segments.len();
        self.push(off_s, Motion::Hold(self.current_f), Vibration::None, None);
        if self.segments.len() > n
            && let Some(last) = self.segments.last_mut()
        {
            last.written = Written::Nothing;
            last.powered = false;
        }
    }

    /// Turns the unit to `f_g` in `move_s` (reference unknown meanwhile). Nothing when it is
    /// already there.
    pub fn move_to(&mut self, f_g: [f64; 3], move_s: f64) {
        if f_g != self.current_f {
            self.push(move_s, Motion::Move { from: self.current_f, to: f_g }, Vibration::None, None);
            self.current_f = f_g;
        }
    }

    /// A commanded ramp to `f_g` in `ramp_s` (reference known) under `vib`.
    pub fn ramp_to(&mut self, f_g: [f64; 3], ramp_s: f64, vib: Vibration<f64>, label: Option<String>) {
        if f_g != self.current_f {
            self.push(ramp_s, Motion::Ramp { from: self.current_f, to: f_g }, vib, label);
            self.current_f = f_g;
        }
    }

    /// Holds the current position for `dwell_s` under `vib`.
    pub fn hold(&mut self, dwell_s: f64, vib: Vibration<f64>, label: Option<String>) {
        self.push(dwell_s, Motion::Hold(self.current_f), vib, label);
    }

    /// The tilter's test positions TP1…TP6 (`which` 1-based), each reached in `move_s` and
    /// held for `dwell_s`.
    pub fn tilter(&mut self, which: &[usize], dwell_s: f64, move_s: f64) {
        for &k in which {
            self.move_to(TILTER_POSITIONS_G[k - 1], move_s);
            self.hold(dwell_s, Vibration::None, Some(format!("TP{k}")));
        }
    }

    /// The tilter's positions placed by hand against their labels, not level: each true force
    /// is the label tilted by an angle uniform in [0, `tilt_max_rad`] towards a uniformly
    /// random direction (drawn from `seed`); the reference cells say the label.
    pub fn tilter_unlevel(&mut self, which: &[usize], dwell_s: f64, move_s: f64, tilt_max_rad: f64, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for &k in which {
            let label = TILTER_POSITIONS_G[k - 1];
            let tilt = tilt_max_rad * rng.random::<f64>();
            let az = 2.0 * std::f64::consts::PI * rng.random::<f64>();
            let (e1, e2) = perpendiculars(&label);
            let f: [f64; 3] =
                std::array::from_fn(|i| label[i] * tilt.cos() + tilt.sin() * (az.cos() * e1[i] + az.sin() * e2[i]));
            self.move_to(f, move_s);
            self.hold(dwell_s, Vibration::None, Some(format!("TP{k}")));
            if let Some(last) = self.segments.last_mut() {
                last.written = Written::Nominal(label);
            }
        }
    }

    /// A calibration by hand: `init_s` still where the unit is, then `holds` orientations
    /// uniform on the sphere (drawn from `seed`), each reached in `move_s` and held for
    /// `dwell_s`. Nothing is written in the reference cells.
    pub fn hand(&mut self, holds: usize, init_s: f64, dwell_s: f64, move_s: f64, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        self.hold(init_s, Vibration::None, None);
        self.hide_last();
        for _ in 0..holds {
            let z = 2.0 * rng.random::<f64>() - 1.0;
            let phi = 2.0 * std::f64::consts::PI * rng.random::<f64>();
            let r = (1.0 - z * z).max(0.0).sqrt();
            self.move_to([r * phi.cos(), r * phi.sin(), z], move_s);
            self.hold(dwell_s, Vibration::None, None);
            self.hide_last();
        }
    }

    fn hide_last(&mut self) {
        if let Some(last) = self.segments.last_mut() {
            last.written = Written::Nothing;
        }
    }

    /// The check positions CP1…CP6 at tilt `theta_deg` (`which` 1-based).
    pub fn check(&mut self, which: &[usize], theta_deg: f64, dwell_s: f64, move_s: f64) {
        let cp = check_positions_g(theta_deg);
        for &k in which {
            self.move_to(cp[k - 1], move_s);
            self.hold(dwell_s, Vibration::None, Some(format!("CP{k}")));
        }
    }

    /// The shake table's ten-position plan (physics §8) for accelerometer `axis`: in each
    /// position TPk a quiet hold of `quiet_s`, then `shake_s` of vibration made by `vib` from
    /// the plan's amplitudes on the unit's axes (peak for sine, σ for random).
    ///
    /// Geometry: in TP1…TP8 IA is tilted by φ_k = (k−1)·45° from the vertical in the IA–PA
    /// plane (static force `cos φ` on IA, `sin φ` on PA); in TP9 (vibration along IA–OA) PA
    /// is vertical, in TP10 (IA–PA) OA is, so IA is horizontal in both.
    pub fn shake_plan(
        &mut self,
        axis: Axis,
        level_g: f64,
        vib: impl Fn([f64; 3]) -> Vibration<f64>,
        quiet_s: f64,
        shake_s: f64,
        move_s: f64,
    ) {
        let plan = ten_position_plan(level_g);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let sin_phi = [0.0, s, 1.0, s, 0.0, -s, -1.0, -s];
        for (k, (a_p3, amp)) in plan.iter().enumerate() {
            let f = match k {
                0..=7 => AccelAxes { ia: *a_p3, pa: sin_phi[k], oa: 0.0 },
                8 => AccelAxes { ia: 0.0, pa: 1.0, oa: 0.0 },
                _ => AccelAxes { ia: 0.0, pa: 0.0, oa: 1.0 },
            };
            self.move_to(to_unit(f, axis), move_s);
            let label = Some(format!("TP{}", k + 1));
            self.hold(quiet_s, Vibration::None, label.clone());
            self.hold(shake_s, vib(to_unit(*amp, axis)), label);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn to_unit_inverts_from_unit() {
        let a = AccelAxes { ia: 1.0, pa: 2.0, oa: 3.0 };
        for axis in Axis::ALL {
            assert_eq!(AccelAxes::from_unit(&to_unit(a, axis), axis), a);
        }
    }

    #[test]
    fn moves_turn_on_the_sphere() {
        let (a, b) = ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]);
        for k in 0..=10 {
            let v = rotate_between(&a, &b, k as f64 / 10.0);
            assert!((norm(&v) - 1.0).abs() < 1e-12);
        }
        let v = rotate_between(&a, &b, 1.0);
        assert!((v[2] + 1.0).abs() < 1e-12);
        let v = rotate_between(&[1.0, 0.0, 0.0], &[0.0, 1.0, 0.0], 0.5);
        assert!((v[0] - v[1]).abs() < 1e-12 && (v[0] - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn shake_plan_static_force_is_one_g_with_ia_at_cos_phi() {
        let mut t = Timeline::new([0.0, 0.0, 1.0]);
        t.shake_plan(Axis::Y, 0.5, |a| Vibration::Harmonic { amp_g: a, freq_hz: 50.0 }, 1.0, 1.0, 1.0);
        let holds: Vec<&Segment> = t.segments.iter().filter(|s| s.reference_known()).collect();
        assert_eq!(holds.len(), 20);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let cos_phi = [1.0, s, 0.0, -s, -1.0, -s, 0.0, s, 0.0, 0.0];
        for (k, pair) in holds.chunks(2).enumerate() {
            let Motion::Hold(f) = pair[0].motion else { panic!() };
            assert!((norm(&f) - 1.0).abs() < 1e-15);
            assert!((f[1] - cos_phi[k]).abs() < 1e-15, "TP{}: {f:?}", k + 1);
            let Vibration::Harmonic { amp_g, .. } = pair[1].vib else { panic!() };
            // Along IA (y) always 0.5 g; TP9 adds OA (x), TP10 PA (z).
            assert_eq!(amp_g[1], 0.5);
            assert_eq!((amp_g[0], amp_g[2]), [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5)][k.saturating_sub(7).min(2)]);
        }
    }
}
