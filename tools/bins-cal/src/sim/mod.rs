//! The simulator: a digital twin of one unit on its rigs, writing recording format v1.
//!
//! | module | owns |
//! |---|---|
//! | [`unit`](mod@unit) | the truth model: T(1) constants with their temperature model (the core's), V(2) nonlinearity, warm-up, noise |
//! | [`thermal`] | chamber → case → die lags, self-heating, thermistor placement and lag, hysteresis |
//! | [`rectify`] | rectified means of V(2) over sine and Gaussian vibration by quadrature |
//! | [`rig`] | the timeline: tilter TP1–TP6, check positions CP1–CP6, shake-table plan, flight ramps |
//! | [`scenario`] | the scenario file (TOML): parsing, checks naming the key, building a [`Simulation`] |
//!
//! Row `k` is logged at `t = k/rate` unless the unit is off then (a power cycle: no row); its
//! signals are the logger's mean over the sample period: the static parts are evaluated at
//! `t`, the vibration enters through its rectified mean (and, optionally, its sampling
//! fluctuation). The generator draws every random number from one ChaCha8 stream in a fixed
//! order, so a seed gives the same file bit for bit on any machine.

pub mod rectify;
pub mod rig;
pub mod scenario;
pub mod thermal;
pub mod unit;

use crate::fsio::AtomicFile;
use crate::progress::Pass;
use crate::recording::{Columns, Row, Writer};
use bins_comp::vibration::Vibration;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rig::Segment;
use std::path::Path;
use thermal::{Thermal, ThermalParams};
use unit::{NoiseParams, NoiseState, Quantiser, UnitModel};

/// Everything a run needs.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// The unit.
    pub unit: UnitModel,
    /// Thermal model.
    pub thermal: ThermalParams,
    /// Noise.
    pub noise: NoiseParams,
    /// The rig program.
    pub segments: Vec<Segment>,
    /// Logger rate \[Hz\].
    pub rate_hz: f64,
    /// Time since power-on at the first row \[s\].
    pub power_on_s: f64,
    /// Whether `chamber_C` is written.
    pub log_chamber: bool,
    /// Comment lines for the file.
    pub comments: Vec<String>,
}

impl Simulation {
    /// Total duration \[s\].
    pub fn duration_s(&self) -> f64 {
        self.segments.iter().map(|s| s.duration_s).sum()
    }

    /// Rows the run writes: every `t = k/rate` inside the duration while the unit is on.
    pub fn n_rows(&self) -> u64 {
        let n = self.n_instants();
        if self.segments.iter().all(|s| s.powered) {
            return n;
        }
        // The instants in each segment the unit is off, by the row generator's own test: row k
        // is in the last segment whose start (summed in order) is at or before k/rate.
        let first_at = |start: f64| {
            let mut k = (start * self.rate_hz).ceil().max(0.0) as u64;
            while k > 0 && (k - 1) as f64 / self.rate_hz >= start {
                k -= 1;
            }
            while (k as f64 / self.rate_hz) < start {
                k += 1;
            }
            k.min(n)
        };
        let (mut start, mut off) = (0.0, 0);
        for (j, s) in self.segments.iter().enumerate() {
            let end = start + s.duration_s;
            if !s.powered {
                let from = if j == 0 { 0 } else { first_at(start) };
                let to = if j + 1 == self.segments.len() { n } else { first_at(end) };
                off += to.saturating_sub(from);
            }
            start = end;
        }
        n - off
    }

    /// The instants `t = k/rate` inside the duration.
    fn n_instants(&self) -> u64 {
        let d = self.duration_s() * self.rate_hz;
        // A duration that is a whole number of periods ends just before its last instant.
        let n = d.ceil();
        if n <= 0.0 { 0 } else { n as u64 }
    }

    /// The columns a run writes.
    pub fn columns(&self) -> Columns {
        Columns { reference: true, chamber: self.log_chamber, pos: true, power: true, extra: Vec::new() }
    }

    /// A row generator for `seed`.
    pub fn rows(&self, seed: u64) -> RowGen<'_> {
        RowGen::new(self, seed)
    }

    /// Every row of the run for `seed`, in memory: for a short design (a proposed test at a
    /// coarse period, a test's case); a long run streams through [`rows`](Self::rows).
    pub fn all_rows(&self, seed: u64) -> Vec<Row> {
        let mut rows = self.rows(seed);
        let mut out = Vec::new();
        let mut row = Row::default();
        while rows.next_row(&mut row) {
            out.push(row.clone());
        }
        out
    }

    /// Writes [`follow`](Self::follow)'s rows for the recording `real` to `output`
    /// (atomically), with the columns of REAL that have a value in some row (columns the format
    /// does not define are dropped). Two passes over REAL, each with a progress bar: the first
    /// finds the columns and checks every row, the second predicts and writes row by row; one
    /// row is held at a time. Errors name the file: REAL unreadable or without a data row.
    pub fn write_follow(&self, real: &Path, output: &Path) -> anyhow::Result<u64> {
        let rec = |e: crate::recording::Error| anyhow::anyhow!("{e}");
        let mut row = Row::default();
        let (mut chamber, mut pos, mut power, mut n) = (false, false, false, 0u64);
        let mut pass = Pass::open(real, "checking").map_err(rec)?;
        while pass.read_row(&mut row).map_err(rec)? {
            chamber |= row.chamber_c.is_some();
            pos |= row.pos.is_some();
            power |= row.power_s.is_some();
            n += 1;
        }
        if n == 0 {
            anyhow::bail!("{}: no data row to follow", real.display());
        }
        let comments = [
            format!("recording format v1 -- predicted by {}", crate::TOOL_VERSION),
            format!(
                "the scenario's unit following {} row for row (reference, temp_C, power_s; no noise)",
                real.display()
            ),
        ];
        let refs: Vec<&str> = comments.iter().map(String::as_str).collect();
        let columns = Columns { reference: true, chamber, pos, power, extra: Vec::new() };
        let mut file = AtomicFile::create(output)?;
        let mut w = Writer::new(file.writer(), output, columns, &refs)?;
        let mut pass = Pass::open(real, "predicting").map_err(rec)?;
        let mut k = 0u64;
        while pass.read_row(&mut row).map_err(rec)? {
            let mut out = self.follow_row(&row);
            out.extra.clear();
            w.write_row(&out)?;
            k += 1;
        }
        w.finish()?;
        file.commit()?;
        Ok(k)
    }

    /// The twin's prediction of a real recording, row for row (`bins-cal simulate --follow`):
    /// the unit at REAL's `temp_C` (the thermistor's reading taken as the constants'
    /// temperature: no lag, no self-heating), REAL's reference specific force and vibration
    /// (rectified through the unit's V(2)), and REAL's `power_s` (or the scenario's power-on
    /// time plus `t_s`) for the warm-up; no noise. REAL's other cells are kept, so the pair
    /// matches row for row; rows whose reference is not known keep REAL's signals (the
    /// diagnosis skips them). The scenario's rig program and thermal chain are not used.
    pub fn follow(&self, real: &[Row]) -> Vec<Row> {
        real.iter().map(|r| self.follow_row(r)).collect()
    }

    /// [`follow`](Self::follow) of one row.
    pub fn follow_row(&self, r: &Row) -> Row {
        let mut row = r.clone();
        let vib = if r.vib_kind.is_none() { Some(Vibration::None) } else { r.vibration() };
        let (Some(f), Some(vib)) = (r.reference_f_g(), vib) else { return row };
        if !r.temp_c.is_finite() {
            return row;
        }
        let rect_g = rectify::rectified_g(&self.unit.cf, &f, &vib);
        let power_s = r.power_s.unwrap_or(self.power_on_s + r.t_s);
        row.u_v = self.unit.signals_v(r.temp_c, &f, &[0.0; 3], &rect_g, power_s, 0.0);
        row
    }

    /// Writes the recording of `sim` for `seed` to `output` atomically; returns the row count.
    pub fn write(&self, scenario_name: &str, seed: u64, output: &Path, progress: bool) -> anyhow::Result<u64> {
        let mut comments = vec![
            format!("recording format v1 -- simulated by {}", crate::TOOL_VERSION),
            format!("scenario: {scenario_name}, seed {seed}"),
        ];
        comments.extend(self.comments.iter().cloned());
        let refs: Vec<&str> = comments.iter().map(String::as_str).collect();
        let mut file = AtomicFile::create(output)?;
        let mut w = Writer::new(file.writer(), output, self.columns(), &refs)?;
        let n = self.n_rows();
        let bar = if progress { indicatif::ProgressBar::new(n) } else { indicatif::ProgressBar::hidden() };
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} rows, {elapsed} (eta {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        let mut rows = self.rows(seed);
        let mut row = Row::default();
        let mut k = 0u64;
        while rows.next_row(&mut row) {
            w.write_row(&row)?;
            k += 1;
            if k.is_multiple_of(65536) {
                bar.set_position(k);
            }
        }
        bar.finish_and_clear();
        w.finish()?;
        file.commit()?;
        Ok(k)
    }
}

/// The rectified means for one (force, vibration) pair, cached while both stay the same.
#[derive(Clone, Debug)]
struct RectCache {
    f: [f64; 3],
    vib: Vibration<f64>,
    rect_g: [f64; 3],
    /// Standard deviation of the sample mean of ξ (random vibration, sampling fluctuation).
    boxcar_sd: f64,
}

/// Produces the rows of a [`Simulation`] one at a time (constant memory).
pub struct RowGen<'a> {
    sim: &'a Simulation,
    rng: ChaCha8Rng,
    thermal: Thermal,
    noise: NoiseState,
    dt: f64,
    k: u64,
    n: u64,
    seg: usize,
    seg_start: f64,
    cache: Option<RectCache>,
    chamber_q: Quantiser,
    bias_play: unit::BiasPlay,
    /// The run time of the last power-on after a time off (`None`: on since the start).
    power_on_t: Option<f64>,
    /// Rows written.
    written: u64,
}

impl<'a> RowGen<'a> {
    fn new(sim: &'a Simulation, seed: u64) -> Self {
        let dt = 1.0 / sim.rate_hz;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut noise = NoiseState::new(sim.noise, dt);
        noise.start(&mut rng);
        let thermal = Thermal::new(sim.thermal, dt, sim.power_on_s);
        RowGen {
            sim,
            rng,
            bias_play: unit::BiasPlay::new(sim.unit.bias_play_width_c, thermal.effective_c),
            thermal,
            noise,
            dt,
            k: 0,
            n: sim.n_instants(),
            seg: 0,
            seg_start: 0.0,
            cache: None,
            chamber_q: Quantiser::new(0.001),
            power_on_t: None,
            written: 0,
        }
    }

    /// Rows left to produce.
    pub fn remaining(&self) -> u64 {
        self.sim.n_rows() - self.written
    }

    /// A new set point and the rate of the move to it.
    fn set_point(&mut self, seg: usize) {
        let s = &self.sim.segments[seg];
        if let Some(c) = s.chamber_c {
            self.thermal.target_c = c;
            self.thermal.rate_c_per_s = s.chamber_rate_c_per_s.unwrap_or(self.sim.thermal.rate_c_per_s);
        }
    }

    /// Fills `row` with the next row; false after the last.
    pub fn next_row(&mut self, row: &mut Row) -> bool {
        loop {
            if self.k >= self.n {
                return false;
            }
            if self.next_instant(row) {
                self.written += 1;
                return true;
            }
        }
    }

    /// Advances to the next instant `t = k/rate`; fills `row` and returns true when the unit is
    /// on then.
    fn next_instant(&mut self, row: &mut Row) -> bool {
        let sim = self.sim;
        let t = self.k as f64 / sim.rate_hz;
        // The segment holding t (segments of zero duration were never pushed).
        let segs = &sim.segments;
        // Every set point on the way counts, also that of a segment shorter than a period; so
        // does every power-on.
        if self.k == 0 {
            self.set_point(0);
        }
        while self.seg + 1 < segs.len() && t >= self.seg_start + segs[self.seg].duration_s {
            self.seg_start += segs[self.seg].duration_s;
            self.seg += 1;
            self.set_point(self.seg);
            if segs[self.seg].powered && !segs[self.seg - 1].powered {
                self.power_on_t = Some(self.seg_start);
            }
        }
        let seg = &segs[self.seg];
        if self.k > 0 {
            self.thermal.step();
        }
        // The die is heated over the next step if the unit is on now.
        self.thermal.powered = seg.powered;
        if !seg.powered {
            // Off: the plays follow the die, nothing is logged, the noise pauses.
            self.bias_play.step(self.thermal.effective_c);
            self.k += 1;
            return false;
        }
        let s = ((t - self.seg_start) / seg.duration_s).clamp(0.0, 1.0);
        let f = seg.f_at(s);
        let vib = if seg.reference_known() { seg.vib } else { Vibration::None };
        let hit = matches!(&self.cache, Some(c) if c.f == f && c.vib == vib);
        if !hit {
            let rect_g = rectify::rectified_g(&self.sim.unit.cf, &f, &vib);
            let boxcar_sd = match vib {
                Vibration::Random { band_hz, .. } => rectify::boxcar_variance(band_hz, self.dt).sqrt(),
                _ => 0.0,
            };
            self.cache = Some(RectCache { f, vib, rect_g, boxcar_sd });
        }
        let (rect_g, boxcar_sd) = self.cache.as_ref().map_or(([0.0; 3], 0.0), |c| (c.rect_g, c.boxcar_sd));
        // The sample's mean of the vibration itself (zero over whole periods).
        let mut vib_mean = [0.0; 3];
        if self.noise.vibration_sampling() {
            match vib {
                Vibration::None => {}
                Vibration::Harmonic { amp_g, freq_hz } => {
                    // Mean of sin ωτ over (t − Δt, t].
                    let w = 2.0 * std::f64::consts::PI * freq_hz;
                    let m = if w * self.dt > 1e-9 {
                        ((w * (t - self.dt)).cos() - (w * t).cos()) / (w * self.dt)
                    } else {
                        (w * t).sin()
                    };
                    vib_mean = amp_g.map(|a| a * m);
                }
                Vibration::Random { sigma_g, .. } => {
                    let z: f64 = self.rng.sample(StandardNormal);
                    vib_mean = sigma_g.map(|sg| sg * boxcar_sd * z);
                }
            }
        }
        let power_s = match self.power_on_t {
            None => self.sim.power_on_s + t,
            Some(on) => t - on,
        };
        let bias_d = self.bias_play.step(self.thermal.effective_c);
        let mut u = self.sim.unit.signals_v(self.thermal.effective_c, &f, &vib_mean, &rect_g, power_s, bias_d);
        self.noise.apply_signals(&mut self.rng, &mut u);
        let temp_c = self.noise.apply_temp(&mut self.rng, self.thermal.thermistor_c);

        row.line = 0;
        row.t_s = t;
        row.u_v = u;
        row.temp_c = temp_c;
        row.chamber_c = self.sim.log_chamber.then(|| self.chamber_q.apply(self.thermal.chamber_c));
        row.power_s = Some(power_s);
        if seg.reference_known() {
            row.f_g = seg.written_f_at(s).map(Some);
            row.set_vibration(&vib);
            match &seg.label {
                Some(l) => match &mut row.pos {
                    Some(p) if p == l => {}
                    _ => row.pos = Some(l.clone()),
                },
                None => row.pos = None,
            }
        } else {
            row.clear_reference();
            row.pos = None;
        }
        self.k += 1;
        true
    }
}
