//! From a SIM/REAL pair of recordings to the per-accelerometer residual in g: row matching,
//! the reference, the scale factors from SIM's own signals, the constant-reference segments,
//! the temperature rate and the white-noise level of each vibration condition.

use super::DiagnoseError;
use super::stats::{chol_solve, dot, median};
use crate::recording::{Row, VibKind};
use bins_comp::vibration::Vibration;
use std::path::Path;

/// The pair, aligned and reduced to the rows with a known reference.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Data rows in each file.
    pub n_total: usize,
    /// Rows left out because their reference is not known.
    pub skipped: usize,
    /// REAL's line number of each used row.
    pub line: Vec<u64>,
    /// `t_s` \[s\].
    pub t: Vec<f64>,
    /// REAL's `temp_C` [°C].
    pub temp: Vec<f64>,
    /// Reference static specific force \[g\].
    pub f: Vec<[f64; 3]>,
    /// Reference vibration.
    pub vib: Vec<Vibration<f64>>,
    /// Vibration condition (kind and level) of each row: index into `vib_names`.
    pub vib_class: Vec<usize>,
    /// Names of the vibration conditions (`none`, `sine 0.8 g`, `random 1.5 g`).
    pub vib_names: Vec<String>,
    /// Position label index (into `pos_names`), when the file has `pos`.
    pub pos: Vec<Option<usize>>,
    /// Position labels.
    pub pos_names: Vec<String>,
    /// `power_s` \[s\] when every used row has it.
    pub power: Option<Vec<f64>>,
    /// REAL's `chamber_C` [°C] when every used row has it (the proposal's thermal path is
    /// identified from it, [`super::propose::identify_thermal`]).
    pub chamber: Option<Vec<f64>>,
    /// Constant-reference segment of each row.
    pub seg: Vec<usize>,
    /// Residual REAL − SIM per accelerometer \[g\].
    pub r: [Vec<f64>; 3],
    /// SIM's departure from its own linear fit `K·f + U0` per accelerometer \[g\]: what the
    /// simulation makes of temperature and nonlinearity.
    pub sim_g: [Vec<f64>; 3],
    /// Scale factors `K_ii` used [V/g].
    pub k_diag: [f64; 3],
    /// Whether each scale factor came from SIM (false: nominal 1 V/g).
    pub k_determined: [bool; 3],
    /// Median sample period \[s\].
    pub dt: f64,
    /// `temp_C` smoothed over ±10 s (at least ±1 row, at most ±50 rows) without rounding the
    /// turns of a ramp ([`smooth_temperature`]): the thermal terms are built from it, so the
    /// thermistor's own noise does not enter the regressors (errors in variables).
    pub temp_s: Vec<f64>,
    /// The resolution of REAL's `temp_C`: its smallest nonzero change between consecutive rows
    /// [°C] (`None` when it never changes). A play narrower than two of these steps is not
    /// resolved by the thermometer ([`super::report`] reports its width as undetermined).
    pub temp_resolution_c: Option<f64>,
    /// SIM's own `temp_C` smoothed as `temp_s` is: SIM's temperature sensitivity is fitted
    /// against it ([`super::mech::fit_sensitivity`]). The same as `temp_s` when SIM follows
    /// REAL's temperature (`--calib`, or a simulation driven by REAL's `temp_C`); a simulation
    /// of the same test with its own thermal path reads its own temperature.
    pub sim_temp_s: Vec<f64>,
    /// Temperature rate (centred difference over about a minute) [°C/s].
    pub dtemp: Vec<f64>,
    /// White-noise variance of the residual at each row \[g²\], per accelerometer (of a block's
    /// mean when the rows are blocks).
    pub r_white: [Vec<f64>; 3],
    /// With rows reduced to blocks ([`Builder::with_blocks`]): the recording's rows in each
    /// block; empty when every row is one of the recording's.
    pub weight: Vec<f64>,
    /// With blocks: the residual's sum of squares about its block mean, per block \[g²\], per
    /// accelerometer (what the block means do not show of the per-row figures).
    pub within: [Vec<f64>; 3],
    /// With blocks: the per-row noise floor measured from consecutive rows (the Allan deviation
    /// at one row, `√(½·mean((r_k − r_{k−1})²))`, over rows without vibration, or all) \[g\].
    pub row_floor: Option<[f64; 3]>,
    /// The first row (or block) of each session, ascending, starting with 0: a session starts
    /// where the time jumps between consecutive lines of the file with the unit unpowered
    /// ([`SESSION_GAP_S`]; `power_s` going back across a longer step than the sampling's). The
    /// noise model's level and the temperature's smoothing restart at each: their state across
    /// the unrecorded time is unknown. A lag or a play runs on through the join
    /// ([`super::mech::lagged`], [`super::mech::play`]). A power cycle within
    /// the sampling (`power_s` going back, no time missing) is not a new session: the
    /// temperature was recorded throughout.
    pub session_starts: Vec<usize>,
    /// The die's rise over the thermistor after each power-on that SIM shows
    /// ([`super::mech::die_rise`]); when present it is in `temp_s` and `sim_temp_s`, which are
    /// then the die's temperature the thermal and temperature terms act on.
    pub die_rise: Option<super::mech::DieRise>,
    /// The die's rise at each power-on that the thermistor misses, as REAL's lag shows it
    /// ([`super::mech::missed_die_rise`]) [°C]; 0 until the diagnosis estimates it, and where
    /// it finds none.
    pub lag_rise_c: f64,
    /// Notes for the report.
    pub notes: Vec<String>,
}

/// A step of `t_s` between consecutive lines longer than this \[s\] (and than
/// [`SESSION_GAP_STEPS`] times the step before it) starts a new session, unless `power_s`
/// advanced across it by at least half of it (the unit stayed powered while the logger
/// paused).
pub const SESSION_GAP_S: f64 = 60.0;

/// See [`SESSION_GAP_S`].
pub const SESSION_GAP_STEPS: f64 = 20.0;

/// Where `power_s` goes back (a power-on), a step of `t_s` longer than this many times the step
/// before it starts a new session: the unit was off for time the record does not hold.
pub const POWER_ON_GAP_STEPS: f64 = 10.0;

impl Prepared {
    /// Finds the die's rise SIM shows ([`super::mech::die_rise`]) and, when there is one, moves
    /// `temp_s` and `sim_temp_s` to the die's temperature, with a note.
    fn take_die_rise(&mut self) {
        let Some(d) = super::mech::die_rise(self) else { return };
        let Some(power) = self.power.as_deref() else { return };
        let offset = d.offset_c(power);
        for (t, o) in self.temp_s.iter_mut().zip(&offset) {
            *t += o;
        }
        for (t, o) in self.sim_temp_s.iter_mut().zip(&offset) {
            *t += o;
        }
        self.notes.push(format!(
            "SIM's die runs {:+.2} °C over the thermistor once settled after each power-on (τ = {:.0} s): at that temperature SIM's sensitivity leaves {:.0} % of what it leaves at the thermistor's; the temperature and thermal terms act on the die's temperature",
            d.amp_c,
            d.tau_s,
            100.0 * d.sim_left_share
        ));
        self.die_rise = Some(d);
    }

    /// The session of each row (index into [`Prepared::session_starts`]).
    pub fn session_of_rows(&self) -> Vec<usize> {
        let mut out = Vec::with_capacity(self.t.len());
        let mut s = 0;
        for i in 0..self.t.len() {
            while s + 1 < self.session_starts.len() && self.session_starts[s + 1] <= i {
                s += 1;
            }
            out.push(s);
        }
        out
    }

    /// The row ranges of the sessions.
    pub fn sessions(&self) -> Vec<std::ops::Range<usize>> {
        session_ranges(&self.session_starts, self.t.len())
    }

    /// One column per session after the first: 1 from its first row on, 0 before (a
    /// Heaviside). With them in a model the level restarts at every session, as a diffuse
    /// start of the noise model's level would.
    pub fn session_columns(&self) -> Vec<Vec<f64>> {
        let n = self.t.len();
        self.session_starts.iter().skip(1).map(|&k| (0..n).map(|i| if i >= k { 1.0 } else { 0.0 }).collect()).collect()
    }
}

/// The ranges `starts[k]..starts[k + 1]` (the last to `n`).
pub fn session_ranges(starts: &[usize], n: usize) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::with_capacity(starts.len());
    for (k, &a) in starts.iter().enumerate() {
        let b = starts.get(k + 1).copied().unwrap_or(n);
        if b > a {
            out.push(a..b);
        }
    }
    if out.is_empty() {
        out.push(0..n);
    }
    out
}

impl Prepared {
    /// The constant-reference runs without vibration, `(first, end)` row ranges, at least
    /// three rows long (all runs when there are none without vibration).
    pub fn static_runs(&self) -> Vec<(usize, usize)> {
        let n = self.t.len();
        let mut runs: Vec<(usize, usize)> = Vec::new();
        let mut s = 0;
        for i in 1..=n {
            if i == n || self.seg[i] != self.seg[s] {
                runs.push((s, i));
                s = i;
            }
        }
        let quiet: Vec<(usize, usize)> =
            runs.iter().copied().filter(|&(a, b)| matches!(self.vib[a], Vibration::None) && b - a >= 3).collect();
        if quiet.is_empty() { runs } else { quiet }
    }
}

/// Axis names.
pub const AXES: [&str; 3] = ["x", "y", "z"];

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

fn opt_same(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => same(a, b),
        (None, None) => true,
        _ => false,
    }
}

/// Aligns a pair held in memory and computes the residual ([`Builder`]). Errors name REAL's
/// file and line.
pub fn prepare(sim: &[Row], real: &[Row], sim_name: &Path, real_name: &Path) -> Result<Prepared, DiagnoseError> {
    prepare_blocks(sim, real, sim_name, real_name, None)
}

/// [`prepare`] with the block choice of [`super::Options::block_s`]: `None` the length the data
/// allow ([`Builder::blocks_from_data`] at [`super::AUTO_BLOCK_ROWS`]); `Some(0)` every row;
/// `Some(s)` blocks of at most `s` seconds ([`Builder::with_blocks`]).
pub fn prepare_blocks(
    sim: &[Row],
    real: &[Row],
    sim_name: &Path,
    real_name: &Path,
    block_s: Option<f64>,
) -> Result<Prepared, DiagnoseError> {
    let (sn, rn) = (sim_name.display(), real_name.display());
    if real.is_empty() || sim.is_empty() {
        let which = if real.is_empty() { &rn } else { &sn };
        return Err(DiagnoseError(format!("{which}: no data rows")));
    }
    if sim.len() != real.len() {
        return Err(DiagnoseError(format!(
            "{rn}: {} data rows but {sn} has {}: SIM and REAL must be the same test, row for row",
            real.len(),
            sim.len()
        )));
    }
    let mut b = Builder::new(sim_name, real_name).choose_blocks(block_s);
    for (s, r) in sim.iter().zip(real) {
        b.push(s, r)?;
    }
    b.finish()
}

/// Builds [`Prepared`] from the pair's rows given one pair at a time (both files read in
/// lockstep: [`super::diagnose_files`]), so neither recording is ever held whole. Each pair is
/// checked as it comes (same time, reference and vibration cells, position); of a usable row
/// only what [`Prepared`] keeps is stored, with SIM's and REAL's signals as the residual and
/// SIM's departure are made of them. The scale factors, segments, smoothed temperature, rate
/// and white-noise levels need every row and are computed by [`Builder::finish`].
pub struct Builder {
    sim_name: String,
    real_name: String,
    n_total: usize,
    any_vib: bool,
    line: Vec<u64>,
    t: Vec<f64>,
    temp: Vec<f64>,
    sim_temp: Vec<f64>,
    f: Vec<[f64; 3]>,
    vib: Vec<Vibration<f64>>,
    vib_class: Vec<usize>,
    vib_names: Vec<String>,
    pos: Vec<Option<usize>>,
    pos_names: Vec<String>,
    power: Vec<f64>,
    power_all: bool,
    power_any: bool,
    /// REAL's `chamber_C` (NaN where a row has none), and whether every row has it.
    chamber: Vec<f64>,
    chamber_all: bool,
    /// REAL − SIM signals [V] (the residual once divided by the scale factors).
    du: [Vec<f64>; 3],
    /// SIM's signals [V] (SIM's departure from its linear fit once that is known).
    sim_u: [Vec<f64>; 3],
    /// REAL's first signals, and whether each has changed since.
    first_u: [f64; 3],
    u_varies: [bool; 3],
    temp_finite: bool,
    temp_same: bool,
    /// The first kept row's `temp_C`.
    first_temp_c: Option<f64>,
    /// The previous row's `temp_C` and the smallest nonzero change between consecutive rows.
    temp_step: (Option<f64>, f64),
    /// Block length \[s\] when the rows are reduced to blocks.
    block_s: Option<f64>,
    /// Rows kept as they are until this many, then blocks of this length \[s\], or of the
    /// length the rows kept allow when `None` ([`Builder::auto_blocks`],
    /// [`Builder::blocks_from_data`]).
    auto: Option<(usize, Option<f64>)>,
    /// What the report says of the reduction (blocks, or every row and why).
    block_note: Option<String>,
    /// Whether blocks taken on reaching the row count are merged at the end so that the
    /// record needs at most `max_blocks` ([`Builder::blocks_from_data`]).
    coarsen: bool,
    /// The most blocks of the default reduction ([`super::MAX_BLOCKS`]; [`Builder::max_blocks`]).
    max_blocks: usize,
    /// The block being filled.
    pending: Option<Pending>,
    /// Rows per block kept.
    weight: Vec<f64>,
    /// With blocks: where REAL's and SIM's `temp_C` readings changed within each block
    /// ([`destep_temperature`]; rows kept as they are show it themselves).
    temp_steps: Vec<ReadingSteps>,
    sim_temp_steps: Vec<ReadingSteps>,
    /// The previous row kept: its `t_s` and REAL's and SIM's `temp_C`.
    last_reading: Option<(f64, f64, f64)>,
    /// Sum of squares of REAL − SIM about the block mean per block [V²].
    within_du: [Vec<f64>; 3],
    /// Squared differences of REAL − SIM between consecutive rows of one constant-reference
    /// run, per vibration class [V²] (the white-noise level's median).
    diff2: Vec<[Vec<f32>; 3]>,
    /// Sum and count of those squared differences on rows without vibration, per axis.
    quiet_diff2: ([f64; 3], usize),
    /// The previous usable row (for the differences and the runs).
    prev: Option<Kept>,
    /// Whether each row (or block) kept starts a session.
    session_start: Vec<bool>,
    /// The previous line's `t_s`, `power_s` and time step (of any line, used or not).
    last_line: Option<(f64, Option<f64>, f64)>,
    /// A session break seen since the last row kept: the next row kept starts a session.
    break_pending: bool,
}

/// A block length chosen from the rows ([`Builder::block_choice`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockChoice {
    /// The block length \[s\].
    pub block_s: f64,
    /// The length the search's time scales allow \[s\] (a third of the shortest time constant
    /// searched, within the temperature's smoothing); `block_s` is longer where the record
    /// would otherwise need more than `max_blocks` blocks.
    pub physics_s: f64,
    /// The most blocks the reduction makes ([`super::MAX_BLOCKS`] by default).
    pub max_blocks: usize,
    /// The rows' median spacing \[s\].
    pub dt_s: f64,
    /// Rows in a full block.
    pub rows: usize,
    /// Per accelerometer: the residual's spread inside the blocks over what its consecutive
    /// differences predict (1 for white noise; [`Builder::block_choice`]).
    pub within_ratio: [f64; 3],
}

impl BlockChoice {
    /// Whether the blocks change nothing the search sees: at least
    /// [`super::BLOCK_MIN_ROWS`] rows a block, no spread inside them beyond
    /// [`super::BLOCK_WITHIN_RATIO`].
    pub fn accepts(&self) -> bool {
        self.rows >= super::BLOCK_MIN_ROWS && self.within_ratio.iter().all(|r| *r <= super::BLOCK_WITHIN_RATIO)
    }

    /// What the length rests on, for the report's note.
    fn describe(&self) -> String {
        let [x, y, z] = self.within_ratio;
        let why = if self.block_s > self.physics_s {
            format!(
                "the record's span over {} blocks; the shortest time constant searched is three blocks",
                self.max_blocks
            )
        } else {
            "a third of the shortest time constant searched and within the temperature's smoothing".to_string()
        };
        format!(
            "{why}; inside a block the residual spreads {x:.3} / {y:.3} / {z:.3}× what its consecutive differences predict"
        )
    }

    /// Why the rows would rather stay whole.
    fn refusal(&self) -> String {
        if self.rows < super::BLOCK_MIN_ROWS {
            return format!("blocks of {:.4} s would hold {} rows", self.block_s, self.rows);
        }
        let (i, r) = self.within_ratio.iter().enumerate().fold((0, 0.0), |b, (i, &r)| if r > b.1 { (i, r) } else { b });
        format!(
            "inside {:.4} s blocks the residual on {} spreads {r:.3}× what its consecutive differences predict (more than {}: structure or correlated noise below the block)",
            self.block_s,
            AXES[i],
            super::BLOCK_WITHIN_RATIO
        )
    }
}

/// What a usable row keeps (before any block).
#[derive(Clone, Copy)]
struct Kept {
    line: u64,
    t: f64,
    temp: f64,
    sim_temp: f64,
    power: f64,
    chamber: f64,
    f: [f64; 3],
    vib: Vibration<f64>,
    vib_class: usize,
    pos: Option<usize>,
    du: [f64; 3],
    sim_u: [f64; 3],
    /// It starts a session.
    session: bool,
}

impl Kept {
    fn run_end(&self) -> RunEnd {
        RunEnd {
            first_line: self.line,
            next_line: self.line + 1,
            f: self.f,
            vib: self.vib,
            pos: self.pos,
            power: self.power,
            session: self.session,
        }
    }
}

/// What decides whether a row or block continues the run of the one before it
/// ([`RunEnd::continued_by`]): the rows in blocks, the blocks merged.
#[derive(Clone, Copy)]
struct RunEnd {
    first_line: u64,
    /// The line after its last row.
    next_line: u64,
    f: [f64; 3],
    vib: Vibration<f64>,
    pos: Option<usize>,
    power: f64,
    /// Its first row starts a session.
    session: bool,
}

impl RunEnd {
    /// The same reference, vibration and position, the next line, no power-on between
    /// (`power_s` does not go back: a mean `power_s` across a power-on would stand for neither
    /// side) and no new session.
    fn continued_by(&self, next: &RunEnd) -> bool {
        self.next_line == next.first_line
            && self.f == next.f
            && self.vib == next.vib
            && self.pos == next.pos
            && next.power >= self.power
            && !next.session
    }
}

/// A block being filled: sums over its rows.
struct Pending {
    line: u64,
    last_line: u64,
    t0: f64,
    n: usize,
    t: f64,
    temp: f64,
    sim_temp: f64,
    power: f64,
    chamber: f64,
    f: [f64; 3],
    vib: Vibration<f64>,
    vib_class: usize,
    pos: Option<usize>,
    du: [f64; 3],
    du2: [f64; 3],
    sim_u: [f64; 3],
    session: bool,
    temp_steps: ReadingSteps,
    sim_temp_steps: ReadingSteps,
}

impl Builder {
    /// Reduces the rows to blocks of at most `block_s` seconds (means of consecutive rows with
    /// one reference, vibration and position, lines without a gap, no power-on between them),
    /// keeping per block the
    /// rows' count and the residual's spread about the mean; the white-noise level comes from
    /// every pair of consecutive rows as it does without blocks. `None`: every row is kept.
    pub fn with_blocks(mut self, block_s: Option<f64>) -> Self {
        self.block_s = block_s;
        self
    }

    /// The block choice of [`super::Options::block_s`] ([`prepare_blocks`]).
    pub fn choose_blocks(self, block_s: Option<f64>) -> Self {
        match block_s {
            None => self.blocks_from_data(super::AUTO_BLOCK_ROWS),
            Some(b) if b > 0.0 => self.with_blocks(Some(b)),
            Some(_) => self,
        }
    }

    /// Keeps every row up to `max_rows` usable rows; on reaching them, turns the rows kept into
    /// blocks of `block_s` seconds ([`Builder::with_blocks`]) and goes on in blocks, so memory
    /// stops growing with the rows.
    pub fn auto_blocks(mut self, max_rows: usize, block_s: f64) -> Self {
        self.auto = Some((max_rows, Some(block_s)));
        self
    }

    /// Keeps every row, then reduces them to blocks of the length the rows allow
    /// ([`Builder::block_choice`]) where the blocks would change nothing the search sees: at
    /// [`Builder::finish`], or on reaching `max_rows` usable rows (then in any case, chosen
    /// from the rows kept, so memory stops growing with the rows).
    pub fn blocks_from_data(mut self, max_rows: usize) -> Self {
        self.auto = Some((max_rows, None));
        self
    }

    /// The most blocks the default reduction makes ([`super::MAX_BLOCKS`] unless set here).
    pub fn max_blocks(mut self, max_blocks: usize) -> Self {
        self.max_blocks = max_blocks;
        self
    }

    /// The block length the rows kept so far allow, and what it rests on. The length is the
    /// shorter of
    ///
    /// - a third of the shortest time constant the search tries on every row
    ///   (`max(3 dt, 1 s)`, `mech::Context::grid`), so that blocks leave the grid as it is, and
    /// - the half-width the thermal regressors' temperature is smoothed over on every row
    ///   (`min(10 s, 50 dt)`, [`smooth_temperature`]), so a block mean averages no more of the
    ///   temperature than the regressors already do.
    ///
    /// Within blocks of that length the reference, vibration and position are constant (a block
    /// ends where they change), so a mechanism's column can vary inside a block only through
    /// something faster than both: what would show as spread of the residual inside the
    /// blocks beyond what its consecutive differences predict. [`BlockChoice::within_ratio`]
    /// measures that on the rows (`Builder::within_ratio`); the blocks are used when it is at most
    /// [`super::BLOCK_WITHIN_RATIO`] on every accelerometer and a block holds at least
    /// [`super::BLOCK_MIN_ROWS`] rows. `None` with fewer than two rows.
    pub fn block_choice(&self) -> Option<BlockChoice> {
        if self.t.len() < 2 || self.block_s.is_some() {
            return None;
        }
        let diffs: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        if diffs.is_empty() {
            return None;
        }
        let dt = median(&diffs);
        let physics_s = ((3.0 * dt).max(1.0) / 3.0).min((50.0 * dt).min(10.0));
        let span_s = self.t[self.t.len() - 1] - self.t[0];
        let block_s = physics_s.max(span_s / self.max_blocks.max(1) as f64);
        // Rows `k` with `k·dt < block_s` (a block takes rows while `t − t0 < block_s`).
        let rows = (block_s / dt - 1e-6).ceil() as usize;
        let within_ratio = if rows >= 2 { self.within_ratio(block_s) } else { [1.0; 3] };
        Some(BlockChoice { block_s, physics_s, max_blocks: self.max_blocks, dt_s: dt, rows, within_ratio })
    }

    /// Per accelerometer, over the rows kept cut into blocks of `block_s` as
    /// [`Builder::with_blocks`] cuts them: the residual's sum of squares about each block's
    /// mean over half the sum of its squared consecutive differences inside the blocks. Both
    /// have the expectation `(rows − 1)·σ²` per block for white noise of any level; structure
    /// inside a block (a fast transient, a step, noise correlated from row to row) raises the
    /// first more than the second.
    fn within_ratio(&self, block_s: f64) -> [f64; 3] {
        let (mut within, mut half_d2) = ([0.0; 3], [0.0; 3]);
        let (mut k0, mut sum, mut sum2, mut m) = (0usize, [0.0; 3], [0.0; 3], 0usize);
        let close = |within: &mut [f64; 3], sum: &[f64; 3], sum2: &[f64; 3], m: usize| {
            if m > 1 {
                for i in 0..3 {
                    within[i] += (sum2[i] - sum[i] * sum[i] / m as f64).max(0.0);
                }
            }
        };
        for k in 0..self.t.len() {
            let joins = k > 0 && self.run_end(k - 1).continued_by(&self.run_end(k)) && self.t[k] - self.t[k0] < block_s;
            if joins {
                for i in 0..3 {
                    let d = self.du[i][k] - self.du[i][k - 1];
                    half_d2[i] += 0.5 * d * d;
                }
            } else {
                close(&mut within, &sum, &sum2, m);
                (k0, sum, sum2, m) = (k, [0.0; 3], [0.0; 3], 0);
            }
            // About the block's first row, so that the sums do not carry the offset.
            for i in 0..3 {
                let v = self.du[i][k] - self.du[i][k0];
                sum[i] += v;
                sum2[i] += v * v;
            }
            m += 1;
        }
        close(&mut within, &sum, &sum2, m);
        [0, 1, 2].map(|i| if half_d2[i] > 0.0 { within[i] / half_d2[i] } else { 1.0 })
    }

    /// An empty builder; `sim_name` and `real_name` name the files in errors.
    pub fn new(sim_name: &Path, real_name: &Path) -> Self {
        Builder {
            sim_name: sim_name.display().to_string(),
            real_name: real_name.display().to_string(),
            n_total: 0,
            any_vib: false,
            line: Vec::new(),
            t: Vec::new(),
            temp: Vec::new(),
            sim_temp: Vec::new(),
            f: Vec::new(),
            vib: Vec::new(),
            vib_class: Vec::new(),
            vib_names: Vec::new(),
            pos: Vec::new(),
            pos_names: Vec::new(),
            power: Vec::new(),
            power_all: true,
            power_any: false,
            chamber: Vec::new(),
            chamber_all: true,
            du: Default::default(),
            sim_u: Default::default(),
            first_u: [0.0; 3],
            u_varies: [false; 3],
            temp_finite: true,
            temp_same: true,
            first_temp_c: None,
            temp_step: (None, f64::INFINITY),
            block_s: None,
            auto: None,
            block_note: None,
            coarsen: false,
            max_blocks: super::MAX_BLOCKS,
            pending: None,
            weight: Vec::new(),
            temp_steps: Vec::new(),
            sim_temp_steps: Vec::new(),
            last_reading: None,
            within_du: Default::default(),
            diff2: Vec::new(),
            quiet_diff2: ([0.0; 3], 0),
            prev: None,
            session_start: Vec::new(),
            last_line: None,
            break_pending: false,
        }
    }

    /// Data rows given so far.
    pub fn rows(&self) -> usize {
        self.n_total
    }

    /// Forgets every row kept so far (not the count of rows given).
    fn clear_used(&mut self) {
        let fresh = Builder::new(Path::new(""), Path::new(""));
        let (sim_name, real_name) = (std::mem::take(&mut self.sim_name), std::mem::take(&mut self.real_name));
        let (n_total, any_vib, block_s, auto, max_blocks, temp_step, last_line) =
            (self.n_total, self.any_vib, self.block_s, self.auto, self.max_blocks, self.temp_step, self.last_line);
        *self =
            Builder { sim_name, real_name, n_total, any_vib, block_s, auto, max_blocks, temp_step, last_line, ..fresh };
    }

    /// Checks one pair (SIM's row `s`, REAL's row `r`) and keeps what the diagnosis needs of it
    /// when its reference is known. Errors name REAL's file and line and SIM's line.
    pub fn push(&mut self, s: &Row, r: &Row) -> Result<(), DiagnoseError> {
        self.n_total += 1;
        // A new session: the time jumps between lines and `power_s` (if any) did not advance
        // with it, or `power_s` goes back across a step longer than the sampling's.
        if let Some((t_prev, p_prev, step_prev)) = self.last_line {
            let step = r.t_s - t_prev;
            let power_on = matches!((p_prev, r.power_s), (Some(a), Some(b)) if b < a);
            let jump = step > SESSION_GAP_S && step > SESSION_GAP_STEPS * step_prev;
            let powered = matches!((p_prev, r.power_s), (Some(a), Some(b)) if b - a >= 0.5 * step);
            if (jump && !powered) || (power_on && step > POWER_ON_GAP_STEPS * step_prev) {
                self.break_pending = true;
            }
            let normal = if jump { step_prev } else { step };
            self.last_line = Some((r.t_s, r.power_s, normal));
        } else {
            self.last_line = Some((r.t_s, r.power_s, f64::INFINITY));
        }
        let (prev, smallest) = &mut self.temp_step;
        if let Some(p) = *prev {
            let d = (r.temp_c - p).abs();
            if d > 0.0 && d < *smallest {
                *smallest = d;
            }
        }
        *prev = Some(r.temp_c);
        let (sn, rn) = (&self.sim_name, &self.real_name);
        let bad = |col: &str, what: String| {
            DiagnoseError(format!(
                "{rn}:{}: column `{col}`: {what} (line {} of {sn}): rows do not match",
                r.line, s.line
            ))
        };
        let cols = ["fx_g", "fy_g", "fz_g"];
        let vcols = ["vib_x_g", "vib_y_g", "vib_z_g"];
        if !same(s.t_s, r.t_s) {
            return Err(bad("t_s", format!("{} s here, {} s in SIM", r.t_s, s.t_s)));
        }
        for i in 0..3 {
            if !opt_same(s.f_g[i], r.f_g[i]) {
                return Err(bad(cols[i], format!("{:?} here, {:?} in SIM", r.f_g[i], s.f_g[i])));
            }
            if !opt_same(s.vib_g[i], r.vib_g[i]) {
                return Err(bad(vcols[i], format!("{:?} here, {:?} in SIM", r.vib_g[i], s.vib_g[i])));
            }
        }
        if s.vib_kind != r.vib_kind {
            return Err(bad("vib_kind", "vibration kind differs".into()));
        }
        if !opt_same(s.vib_hz, r.vib_hz) || !opt_same(s.vib_bw_hz, r.vib_bw_hz) {
            return Err(bad("vib_hz", "vibration frequency or band differs".into()));
        }
        if s.pos != r.pos {
            return Err(bad("pos", format!("{:?} here, {:?} in SIM", r.pos, s.pos)));
        }
        // Without `vib_kind` anywhere every row is taken as without vibration; with it, a row
        // is used only when its vibration is known. Until the first row with `vib_kind` the
        // former holds; at it, the rows kept (none of which had `vib_kind`) are dropped.
        if r.vib_kind.is_some() && !self.any_vib {
            self.any_vib = true;
            self.clear_used();
        }
        let Some(f) = r.reference_f_g() else { return Ok(()) };
        let vib = if self.any_vib {
            match r.vibration() {
                Some(v) if v.is_valid() => v,
                _ => return Ok(()),
            }
        } else {
            Vibration::None
        };
        if self.t.is_empty() && self.pending.is_none() {
            self.first_u = r.u_v;
        }
        for i in 0..3 {
            self.u_varies[i] |= r.u_v[i] != self.first_u[i];
        }
        self.temp_finite &= r.temp_c.is_finite();
        self.temp_same &= self.first_temp_c.is_none_or(|t0| r.temp_c == t0);
        self.first_temp_c.get_or_insert(r.temp_c);
        let vib_class = {
            let name = match (r.vib_kind, &vib) {
                (_, Vibration::None) | (None, _) | (Some(VibKind::None), _) => "none".to_string(),
                (Some(k), v) => format!("{} {:.3} g", k.as_str(), v.level_g()),
            };
            match self.vib_names.iter().position(|x| *x == name) {
                Some(p) => p,
                None => {
                    self.vib_names.push(name);
                    self.vib_names.len() - 1
                }
            }
        };
        let pos = r.pos.as_ref().map(|p| match self.pos_names.iter().position(|x| x == p) {
            Some(i) => i,
            None => {
                self.pos_names.push(p.clone());
                self.pos_names.len() - 1
            }
        });
        self.power_all &= r.power_s.is_some();
        self.chamber_all &= r.chamber_c.is_some();
        self.power_any |= r.power_s.is_some();
        let du = [0, 1, 2].map(|i| r.u_v[i] - s.u_v[i]);
        let k = Kept {
            line: r.line,
            t: r.t_s,
            temp: r.temp_c,
            sim_temp: s.temp_c,
            power: r.power_s.unwrap_or(0.0),
            chamber: r.chamber_c.unwrap_or(f64::NAN),
            f,
            vib,
            vib_class,
            pos,
            du,
            sim_u: s.u_v,
            session: std::mem::take(&mut self.break_pending) && !(self.t.is_empty() && self.pending.is_none()),
        };
        self.keep(k);
        Ok(())
    }

    /// Keeps one usable row: as it is, or into the block being filled.
    fn keep(&mut self, k: Kept) {
        let Kept { line, t, temp, sim_temp, power, chamber, f, vib, vib_class, pos, du, sim_u, session } = k;
        // The readings' changes since the previous row kept (none across a session's start).
        let last = if session { None } else { self.last_reading };
        let temp_steps = ReadingSteps::between(last.map(|(t, v, _)| (t, v)), t, temp);
        let sim_temp_steps = ReadingSteps::between(last.map(|(t, _, v)| (t, v)), t, sim_temp);
        self.last_reading = Some((t, temp, sim_temp));
        let Some(block_s) = self.block_s else {
            self.session_start.push(session);
            for i in 0..3 {
                self.du[i].push(du[i]);
                self.sim_u[i].push(sim_u[i]);
            }
            self.power.push(power);
            self.chamber.push(chamber);
            self.line.push(line);
            self.t.push(t);
            self.temp.push(temp);
            self.sim_temp.push(sim_temp);
            self.f.push(f);
            self.vib.push(vib);
            self.vib_class.push(vib_class);
            self.pos.push(pos);
            if let Some((max_rows, fixed)) = self.auto
                && self.t.len() >= max_rows
            {
                let block_s = match fixed {
                    Some(b) => {
                        self.block_note = Some(format!(
                            "more than {max_rows} rows: reduced to means over blocks of {b} s, the noise floor and held-out figures per row (every row: --block-s 0)"
                        ));
                        b
                    }
                    None => {
                        self.coarsen = true;
                        self.forced_blocks(max_rows)
                    }
                };
                self.switch_to_blocks(block_s);
            }
            return;
        };
        // The same run as the previous row, no longer gap than a block.
        let run = self.prev.as_ref().is_some_and(|p| p.run_end().continued_by(&k.run_end()) && t - p.t <= block_s);
        if run && let Some(p) = &self.prev {
            while self.diff2.len() <= vib_class {
                self.diff2.push(Default::default());
            }
            for i in 0..3 {
                let d = du[i] - p.du[i];
                self.diff2[vib_class][i].push((d * d) as f32);
                if matches!(vib, Vibration::None) {
                    self.quiet_diff2.0[i] += d * d;
                }
            }
            if matches!(vib, Vibration::None) {
                self.quiet_diff2.1 += 1;
            }
        }
        let joins = run && self.pending.as_ref().is_some_and(|b| t - b.t0 < block_s);
        if !joins {
            self.flush();
        }
        let b = self.pending.get_or_insert(Pending {
            line,
            last_line: line,
            t0: t,
            n: 0,
            t: 0.0,
            temp: 0.0,
            sim_temp: 0.0,
            power: 0.0,
            chamber: 0.0,
            f,
            vib,
            vib_class,
            pos,
            du: [0.0; 3],
            du2: [0.0; 3],
            sim_u: [0.0; 3],
            session,
            temp_steps: ReadingSteps::default(),
            sim_temp_steps: ReadingSteps::default(),
        });
        b.n += 1;
        b.temp_steps.add(&temp_steps);
        b.sim_temp_steps.add(&sim_temp_steps);
        b.last_line = line;
        b.t += t;
        b.temp += temp;
        b.sim_temp += sim_temp;
        b.power += power;
        b.chamber += chamber;
        for i in 0..3 {
            b.du[i] += du[i];
            b.du2[i] += du[i] * du[i];
            b.sim_u[i] += sim_u[i];
        }
        self.prev = Some(k);
    }

    /// The block length taken on reaching `max_rows` rows with [`Builder::blocks_from_data`]:
    /// [`Builder::block_choice`]'s, but at least [`super::BLOCK_MIN_ROWS`] rows, and taken
    /// even where the rows would rather stay whole (the note says so).
    fn forced_blocks(&mut self, max_rows: usize) -> f64 {
        let c = self.block_choice().unwrap_or(BlockChoice {
            block_s: 1.0,
            physics_s: 1.0,
            max_blocks: self.max_blocks,
            dt_s: 1.0,
            rows: 1,
            within_ratio: [1.0; 3],
        });
        let block_s = c.block_s.max(super::BLOCK_MIN_ROWS as f64 * c.dt_s);
        let rows = (block_s / c.dt_s - 1e-6).ceil() as usize;
        let why = if c.accepts() { c.describe() } else { format!("{}; taken although {}", c.describe(), c.refusal()) };
        self.block_note = Some(format!(
            "more than {max_rows} rows: reduced to means over blocks of {block_s:.4} s ({rows} rows) for memory ({why}); the noise floor and held-out figures per row (every row: --block-s 0)"
        ));
        block_s
    }

    /// Turns the rows kept so far into blocks of `block_s` and keeps blocks from now on.
    fn switch_to_blocks(&mut self, block_s: f64) {
        self.auto = None;
        self.block_s = Some(block_s);
        let line = std::mem::take(&mut self.line);
        let t = std::mem::take(&mut self.t);
        let temp = std::mem::take(&mut self.temp);
        let sim_temp = std::mem::take(&mut self.sim_temp);
        let power = std::mem::take(&mut self.power);
        let chamber = std::mem::take(&mut self.chamber);
        let f = std::mem::take(&mut self.f);
        let vib = std::mem::take(&mut self.vib);
        let vib_class = std::mem::take(&mut self.vib_class);
        let pos = std::mem::take(&mut self.pos);
        let du = std::mem::take(&mut self.du);
        let sim_u = std::mem::take(&mut self.sim_u);
        let session = std::mem::take(&mut self.session_start);
        self.temp_steps.clear();
        self.sim_temp_steps.clear();
        self.last_reading = None;
        for k in 0..t.len() {
            self.keep(Kept {
                line: line[k],
                t: t[k],
                temp: temp[k],
                sim_temp: sim_temp[k],
                power: power[k],
                chamber: chamber[k],
                f: f[k],
                vib: vib[k],
                vib_class: vib_class[k],
                pos: pos[k],
                du: [du[0][k], du[1][k], du[2][k]],
                sim_u: [sim_u[0][k], sim_u[1][k], sim_u[2][k]],
                session: session[k],
            });
        }
    }

    /// The run end of row (or block) `i` kept.
    fn run_end(&self, i: usize) -> RunEnd {
        let rows = self.weight.get(i).map_or(1, |w| *w as u64);
        RunEnd {
            first_line: self.line[i],
            next_line: self.line[i] + rows,
            f: self.f[i],
            vib: self.vib[i],
            pos: self.pos[i],
            power: self.power[i],
            session: self.session_start[i],
        }
    }

    /// Merges the blocks kept, `k` consecutive ones of one run at a time (one reference,
    /// vibration and position, no gap in the lines, no power-on): row-weighted means, summed rows, and the
    /// spread about the merged mean (each block's spread plus its rows times its mean's
    /// squared distance from the merged mean), as blocks `k` times longer would have kept.
    fn merge_blocks(&mut self, k: usize) {
        let n = self.weight.len();
        let mut out = Builder::new(Path::new(""), Path::new(""));
        let mut j = 0;
        while j < n {
            let mut e = j + 1;
            while e < n && e - j < k && self.run_end(e - 1).continued_by(&self.run_end(e)) {
                e += 1;
            }
            let w: f64 = self.weight[j..e].iter().sum();
            let mean = |v: &[f64]| (j..e).map(|i| self.weight[i] * v[i]).sum::<f64>() / w;
            out.line.push(self.line[j]);
            out.t.push(mean(&self.t));
            out.temp.push(mean(&self.temp));
            out.sim_temp.push(mean(&self.sim_temp));
            out.power.push(mean(&self.power));
            out.chamber.push(mean(&self.chamber));
            out.f.push(self.f[j]);
            out.vib.push(self.vib[j]);
            out.vib_class.push(self.vib_class[j]);
            out.pos.push(self.pos[j]);
            out.session_start.push(self.session_start[j]);
            out.weight.push(w);
            out.temp_steps.push(ReadingSteps::total(&self.temp_steps[j..e]));
            out.sim_temp_steps.push(ReadingSteps::total(&self.sim_temp_steps[j..e]));
            for a in 0..3 {
                let m = mean(&self.du[a]);
                let spread: f64 =
                    (j..e).map(|i| self.within_du[a][i] + self.weight[i] * (self.du[a][i] - m).powi(2)).sum();
                out.du[a].push(m);
                out.sim_u[a].push(mean(&self.sim_u[a]));
                out.within_du[a].push(spread);
            }
            j = e;
        }
        self.line = out.line;
        self.t = out.t;
        self.temp = out.temp;
        self.sim_temp = out.sim_temp;
        self.power = out.power;
        self.chamber = out.chamber;
        self.f = out.f;
        self.vib = out.vib;
        self.vib_class = out.vib_class;
        self.pos = out.pos;
        self.session_start = out.session_start;
        self.weight = out.weight;
        self.temp_steps = out.temp_steps;
        self.sim_temp_steps = out.sim_temp_steps;
        self.du = out.du;
        self.sim_u = out.sim_u;
        self.within_du = out.within_du;
    }

    /// Closes the block being filled: its means, count and spread are kept.
    fn flush(&mut self) {
        let Some(b) = self.pending.take() else { return };
        let n = b.n as f64;
        self.line.push(b.line);
        self.t.push(b.t / n);
        self.temp.push(b.temp / n);
        self.sim_temp.push(b.sim_temp / n);
        self.power.push(b.power / n);
        self.chamber.push(b.chamber / n);
        self.f.push(b.f);
        self.vib.push(b.vib);
        self.vib_class.push(b.vib_class);
        self.pos.push(b.pos);
        self.session_start.push(b.session);
        self.weight.push(n);
        self.temp_steps.push(b.temp_steps);
        self.sim_temp_steps.push(b.sim_temp_steps);
        for i in 0..3 {
            let m = b.du[i] / n;
            self.du[i].push(m);
            self.sim_u[i].push(b.sim_u[i] / n);
            self.within_du[i].push((b.du2[i] - n * m * m).max(0.0));
        }
    }

    /// The prepared pair: scale factors, residual, segments, temperature rate and white-noise
    /// levels from the rows kept.
    pub fn finish(mut self) -> Result<Prepared, DiagnoseError> {
        if let Some((_, None)) = self.auto
            && let Some(c) = self.block_choice()
        {
            if c.accepts() {
                self.block_note = Some(format!(
                    "reduced to means over blocks of {:.4} s ({} rows; {}); the noise floor and held-out figures per row (every row: --block-s 0)",
                    c.block_s,
                    c.rows,
                    c.describe()
                ));
                self.switch_to_blocks(c.block_s);
            } else if c.rows >= super::BLOCK_MIN_ROWS {
                self.block_note = Some(format!("every row kept: {}", c.refusal()));
            }
        }
        self.flush();
        if self.coarsen && self.weight.len() > self.max_blocks {
            let k = self.weight.len().div_ceil(self.max_blocks.max(1));
            let b = self.block_s.unwrap_or(0.0) * k as f64;
            self.merge_blocks(k);
            self.block_s = Some(b);
            if let Some(note) = &mut self.block_note {
                note.push_str(&format!(
                    "; then merged {k} at a time into blocks of {b:.4} s, so that the record needs at most {} (the shortest time constant searched is three blocks)",
                    self.max_blocks
                ));
            }
        }
        let rn = self.real_name.as_str();
        let Builder {
            n_total,
            any_vib,
            line,
            t,
            temp,
            sim_temp,
            f,
            vib,
            vib_class,
            vib_names,
            pos,
            pos_names,
            power,
            power_all,
            power_any,
            chamber,
            chamber_all,
            du,
            sim_u,
            first_u,
            u_varies,
            temp_finite,
            temp_same,
            block_s,
            weight,
            within_du,
            diff2,
            quiet_diff2,
            block_note,
            temp_step,
            session_start,
            temp_steps,
            sim_temp_steps,
            ..
        } = self;
        let temp_resolution_c = temp_step.1.is_finite().then_some(temp_step.1);
        let blocked = block_s.is_some();
        let mut notes = Vec::new();
        notes.extend(block_note);
        if !any_vib {
            notes.push("no vib_kind in the recordings: every row taken as without vibration".to_string());
        }
        if t.is_empty() {
            return Err(DiagnoseError(format!(
                "{rn}: no row has a known reference (fx_g, fy_g, fz_g{}): diagnosis needs what the rig applied",
                if any_vib { " and the vibration cells" } else { "" }
            )));
        }
        let n = t.len();
        let used = if blocked { weight.iter().sum::<f64>() as usize } else { n };
        let skipped = n_total - used;
        if skipped > 0 {
            notes.push(format!("{skipped} of {n_total} rows skipped: reference not known"));
        }
        // Constant signals: a REAL channel that never changes is dead; a constant SIM channel
        // is legitimate (one orientation, one temperature, no noise) and only costs the scale
        // factor.
        for (i, c) in ["ux_V", "uy_V", "uz_V"].iter().enumerate() {
            if !u_varies[i] {
                let first = first_u[i];
                return Err(DiagnoseError(format!(
                    "{rn}: column `{c}` is constant ({first} V) over the {n} rows with a known reference: no signal"
                )));
            }
        }
        if temp_finite && temp_same {
            notes.push("temp_C is constant: no thermal mechanism can be tried".into());
        }
        let diffs: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let dt = if diffs.is_empty() { 1.0 } else { median(&diffs) };
        drop(diffs);
        let power = if power_all {
            Some(power)
        } else {
            if power_any {
                notes.push("power_s not known on every row: turn-on mechanisms not tried".into());
            }
            None
        };
        let session_starts: Vec<usize> = std::iter::once(0).chain((1..n).filter(|&i| session_start[i])).collect();
        drop(session_start);
        if session_starts.len() > 1 {
            notes.push(format!(
                "{} sessions (the time jumping with the unit unpowered): the noise model's level and the temperature's smoothing restart at each, the thermal terms' lags and plays run on from their state at the last reading; the figures remove one offset per session",
                session_starts.len()
            ));
        }
        let sessions = session_ranges(&session_starts, n);
        // Segments: a new one where the reference changes, time jumps or a session starts.
        let mut seg = vec![0usize; n];
        for i in 1..n {
            let change = session_starts.binary_search(&i).is_ok()
                || f[i] != f[i - 1]
                || vib[i] != vib[i - 1]
                || pos[i] != pos[i - 1]
                || t[i] - t[i - 1] > 3.0 * dt
                || (line[i] > 0 && line[i] != line[i - 1] + if blocked { weight[i - 1] as u64 } else { 1 });
            seg[i] = seg[i - 1] + usize::from(change);
        }

        // Scale factors from SIM: u_i = Σ K_ij f_j + U0_i on rows without vibration (all rows if
        // none), columns scaled to unit norm.
        let quiet: Vec<usize> = (0..n).filter(|&i| matches!(vib[i], Vibration::None)).collect();
        let rows_k: Vec<usize> = if quiet.len() >= 4 { quiet } else { (0..n).collect() };
        let design: Vec<Vec<f64>> =
            (0..4).map(|j| rows_k.iter().map(|&i| if j < 3 { f[i][j] } else { 1.0 }).collect()).collect();
        let norms: Vec<f64> = design.iter().map(|c| dot(c, c).sqrt()).collect();
        let mut gram = vec![0.0; 16];
        for a in 0..4 {
            for b in 0..4 {
                gram[a * 4 + b] = if norms[a] > 0.0 && norms[b] > 0.0 {
                    dot(&design[a], &design[b]) / (norms[a] * norms[b])
                } else if a == b {
                    1.0
                } else {
                    0.0
                };
            }
        }
        let mut k_full = [[0.0; 3]; 3];
        let mut u0 = [0.0; 3];
        let mut k_diag = [1.0; 3];
        let mut k_determined = [false; 3];
        for i in 0..3 {
            let u: Vec<f64> = rows_k.iter().map(|&r| sim_u[i][r]).collect();
            let b: Vec<f64> =
                (0..4).map(|j| if norms[j] > 0.0 { dot(&design[j], &u) / norms[j] } else { 0.0 }).collect();
            let ok = norms[i] > 0.0 && norms[3] > 0.0;
            let sol = if ok { chol_solve(&gram, &b, 4, 1e-9) } else { None };
            match sol {
                Some((x, _)) if (x[i] / norms[i]).abs() > 1e-9 => {
                    for j in 0..4 {
                        let v = if norms[j] > 0.0 { x[j] / norms[j] } else { 0.0 };
                        if j < 3 {
                            k_full[i][j] = v;
                        } else {
                            u0[i] = v;
                        }
                    }
                    k_diag[i] = k_full[i][i];
                    k_determined[i] = true;
                }
                _ => {
                    let mut uu: Vec<f64> = sim_u[i].clone();
                    u0[i] = median(&uu);
                    uu.clear();
                    notes.push(format!(
                    "scale factor of accelerometer {} not determinable from SIM (too few orientations): residual in V at a nominal 1 V/g",
                    AXES[i]
                ));
                }
            }
        }
        let mut r: [Vec<f64>; 3] = du;
        let mut sim_g: [Vec<f64>; 3] = sim_u;
        for i in 0..3 {
            r[i].iter_mut().for_each(|v| *v /= k_diag[i]);
            for (k, v) in sim_g[i].iter_mut().enumerate() {
                let lin: f64 = (0..3).map(|j| k_full[i][j] * f[k][j]).sum::<f64>() + u0[i];
                *v = (*v - lin) / k_diag[i];
            }
        }
        // Temperature rate: centred difference over ±max(30 s, 15 dt).
        let w = (30.0f64).max(15.0 * dt);
        let mut dtemp = vec![0.0; n];
        for sess in &sessions {
            let (mut lo, mut hi) = (sess.start, sess.start);
            for i in sess.clone() {
                while t[i] - t[lo] > w {
                    lo += 1;
                }
                while hi + 1 < sess.end && t[hi + 1] - t[i] <= w {
                    hi += 1;
                }
                if t[hi] > t[lo] {
                    dtemp[i] = (temp[hi] - temp[lo]) / (t[hi] - t[lo]);
                }
            }
        }
        // ±10 s, at least ±1 row, at most ±50 of the recording's rows: with blocks, the same
        // span in seconds (at least ±1 block), so blocks smooth as the rows would.
        let half = if blocked {
            let dt_row = dt / median(&weight).max(1.0);
            ((10.0f64.min(50.0 * dt_row) / dt).round() as usize).max(1)
        } else {
            ((10.0 / dt).round() as usize).clamp(1, 50)
        };
        let smooth = |x: &[f64], steps: &[ReadingSteps]| -> Vec<f64> {
            sessions
                .iter()
                .flat_map(|r| {
                    let (t, x) = (&t[r.clone()], &x[r.clone()]);
                    let of_rows;
                    let steps = if blocked {
                        &steps[r.clone()]
                    } else {
                        of_rows = ReadingSteps::of_rows(t, x);
                        &of_rows[..]
                    };
                    smooth_temperature(t, destep_temperature(t, x, steps).as_deref().unwrap_or(x), half)
                })
                .collect()
        };
        let temp_s = smooth(&temp, &temp_steps);
        // SIM's own temperature: what SIM's sensitivity is a function of. It is REAL's when SIM
        // follows REAL's temperature; a simulation with its own thermal path reads its own.
        let sim_temp_s = if sim_temp == temp {
            temp_s.clone()
        } else {
            let s = smooth(&sim_temp, &sim_temp_steps);
            let (mut worst, mut at, mut ss) = (0.0f64, 0usize, 0.0);
            for k in 0..n {
                let d = temp_s[k] - s[k];
                ss += d * d;
                if d.abs() > worst.abs() {
                    (worst, at) = (d, k);
                }
            }
            notes.push(format!(
                "SIM's temp_C is not REAL's: smoothed, REAL − SIM is {worst:+.3} °C at its largest (t = {:.0} s), {:.3} °C RMS; SIM's temperature sensitivity is fitted against SIM's own temp_C, the thermal terms are built from REAL's",
                t[at],
                (ss / n.max(1) as f64).sqrt()
            ));
            s
        };
        // White noise per vibration class from within-segment differences (robust: median of
        // squared differences / (2·0.4549)).
        let mut r_white: [Vec<f64>; 3] = Default::default();
        for i in 0..3 {
            let mut per_class: Vec<Vec<f64>> = vec![Vec::new(); vib_names.len()];
            for k in 1..n {
                if seg[k] == seg[k - 1] {
                    let d = r[i][k] - r[i][k - 1];
                    per_class[vib_class[k]].push(d * d);
                }
            }
            let all: Vec<f64> = per_class.iter().flatten().copied().collect();
            let global = if all.is_empty() { 0.0 } else { median(&all) / (2.0 * 0.454_936_4) };
            let floor = {
                let scale = r[i].iter().fold(0.0f64, |m, v| m.max(v.abs()));
                (1e-9 * scale).powi(2).max(1e-30)
            };
            let class_var: Vec<f64> = per_class
                .iter()
                .map(|d| if d.len() >= 20 { median(d) / (2.0 * 0.454_936_4) } else { global })
                .map(|v| v.max(floor))
                .collect();
            r_white[i] = vib_class.iter().map(|&c| class_var[c]).collect();
        }
        let mut within: [Vec<f64>; 3] = Default::default();
        let mut row_floor = None;
        if blocked {
            // The per-row white level from the rows' own differences (not the blocks'), each
            // block's mean carrying 1/rows of it; the blocks' spread kept in g².
            let mut floor_g = [0.0; 3];
            for i in 0..3 {
                let k2 = k_diag[i] * k_diag[i];
                let med = |d: &[f32]| {
                    let v: Vec<f64> = d.iter().map(|&x| f64::from(x)).collect();
                    median(&v) / (2.0 * 0.454_936_4) / k2
                };
                let all: Vec<f32> = diff2.iter().flat_map(|c| c[i].iter().copied()).collect();
                let global = if all.is_empty() { 0.0 } else { med(&all) };
                let floor = {
                    let scale = r[i].iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    (1e-9 * scale).powi(2).max(1e-30)
                };
                let class_var: Vec<f64> = (0..vib_names.len())
                    .map(|c| match diff2.get(c) {
                        Some(d) if d[i].len() >= 20 => med(&d[i]),
                        _ => global,
                    })
                    .map(|v| v.max(floor))
                    .collect();
                r_white[i] = vib_class.iter().zip(&weight).map(|(&c, w)| class_var[c] / w).collect();
                within[i] = within_du[i].iter().map(|v| v / k2).collect();
                let (sum, count) = if quiet_diff2.1 > 0 {
                    (quiet_diff2.0[i], quiet_diff2.1)
                } else {
                    (all.iter().map(|&x| f64::from(x)).sum(), all.len())
                };
                floor_g[i] = (0.5 * sum / count.max(1) as f64 / k2).sqrt();
            }
            row_floor = Some(floor_g);
        }
        let mut p = Prepared {
            n_total,
            skipped,
            line,
            t,
            temp,
            f,
            vib,
            vib_class,
            vib_names,
            pos,
            pos_names,
            power,
            chamber: if chamber_all && !chamber.is_empty() { Some(chamber) } else { None },
            seg,
            r,
            sim_g,
            k_diag,
            k_determined,
            dt,
            temp_s,
            sim_temp_s,
            temp_resolution_c,
            dtemp,
            r_white,
            weight,
            within,
            row_floor,
            session_starts,
            notes,
            die_rise: None,
            lag_rise_c: 0.0,
        };
        p.take_die_rise();
        Ok(p)
    }
}

/// Mean square residual of the least-squares line through `(t, x)` over rows `lo..=hi`, and
/// the line's value at `t_at`.
fn line_fit(t: &[f64], x: &[f64], lo: usize, hi: usize, t_at: f64) -> (f64, f64) {
    let m = (hi - lo + 1) as f64;
    let (tm, xm) = (t[lo..=hi].iter().sum::<f64>() / m, x[lo..=hi].iter().sum::<f64>() / m);
    let (mut stt, mut stx, mut sxx) = (0.0, 0.0, 0.0);
    for k in lo..=hi {
        let (dt, dx) = (t[k] - tm, x[k] - xm);
        stt += dt * dt;
        stx += dt * dx;
        sxx += dx * dx;
    }
    let slope = if stt > 0.0 { stx / stt } else { 0.0 };
    let sse = (sxx - slope * stx).max(0.0);
    (sse / (m - 2.0).max(1.0), xm + slope * (t_at - tm))
}

/// Share of consecutive rows with the same reading from which `temp_C` counts as stepped
/// ([`destep_temperature`]). A reading whose noise is a fair part of its step is dithered: its
/// mean over the smoothing window follows the temperature to a small part of a step (to 5 % of
/// it with a noise of 0.3 step), while its changes, crowding at the steps' edges, would pull the
/// line toward them. On a slow ramp rows hold their reading 0.94 of the time with a noise of
/// 0.05 step, 0.89 with 0.1, 0.77 with 0.2 and 0.66 with 0.3 (simulated, a step every 20 rows or
/// more); clean steps fewer than five rows apart hold less, and need no destepping: the ±10 s
/// smoothing spans several of their periods.
pub const STEPPED_SHARE: f64 = 0.8;

/// Where a `temp_C` reading changed within the span of one row or block kept: the sums of the
/// changes' mid-times and mid-values, their count, and the count of rows that held the
/// previous row's reading ([`destep_temperature`]). A row's span reaches back to the previous
/// row kept; a block's is its rows'.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReadingSteps {
    /// Sum of the changes' mid-times \[s\].
    pub t_sum_s: f64,
    /// Sum of the changes' mid-values [°C].
    pub value_sum_c: f64,
    /// Changes of the reading from one row to the next.
    pub changes: u32,
    /// Rows that held the previous row's reading.
    pub held: u32,
}

impl ReadingSteps {
    /// The step (or hold) from the previous row's `(t_s, temp_C)` to this row's.
    pub fn between(prev: Option<(f64, f64)>, t_s: f64, temp_c: f64) -> ReadingSteps {
        match prev {
            Some((_, v)) if v == temp_c => ReadingSteps { held: 1, ..Default::default() },
            Some((tp, v)) => {
                ReadingSteps { t_sum_s: 0.5 * (tp + t_s), value_sum_c: 0.5 * (v + temp_c), changes: 1, held: 0 }
            }
            None => ReadingSteps::default(),
        }
    }

    /// The steps of a row's or block's rows one after another.
    pub fn add(&mut self, other: &ReadingSteps) {
        self.t_sum_s += other.t_sum_s;
        self.value_sum_c += other.value_sum_c;
        self.changes += other.changes;
        self.held += other.held;
    }

    /// The steps of consecutive rows or blocks as one block's.
    pub fn total(steps: &[ReadingSteps]) -> ReadingSteps {
        let mut s = ReadingSteps::default();
        steps.iter().for_each(|x| s.add(x));
        s
    }

    /// The steps of each of a run of rows.
    pub fn of_rows(t_s: &[f64], temp_c: &[f64]) -> Vec<ReadingSteps> {
        (0..t_s.len().min(temp_c.len()))
            .map(|k| ReadingSteps::between(k.checked_sub(1).map(|p| (t_s[p], temp_c[p])), t_s[k], temp_c[k]))
            .collect()
    }
}

/// A stepped temperature reading (a thermistor read to 1/16 °C, where the reading holds for
/// most rows between its steps) as the temperature between its steps; `None` where fewer than
/// [`STEPPED_SHARE`] of consecutive rows hold the same reading. `temp` is the reading (or its
/// block means) at `t`; `steps` where it changed within each ([`ReadingSteps`]).
///
/// Where the reading changes between two rows, the temperature crossed the midpoint of the two
/// readings between them: each change is a point (mid-time, mid-value) known to within the
/// reading's noise, and the changes within one row's or block's span are taken as one point,
/// their mean. The temperature is the line between consecutive such points (before the first
/// and after the last, the reading itself). A staircase is off by up to half a step, in a
/// sawtooth whose period is the time between steps; on a slow ramp that period is longer than
/// the smoothing window of [`smooth_temperature`], and the sawtooth, times a large temperature
/// coefficient, is structure a short thermal lag of the staircase fits (on the user-profile
/// draws of docs/diagnosis-blind.md, a lag named beside a large bias tempco read to 1/16 °C).
/// Block means alone do not say where a step fell: a block that straddles it holds a mean
/// between the two readings, the reading's noise spreads a step over several such blocks, and
/// the line through the block means' own changes keeps most of the staircase (on a warming
/// read to 1/16 °C at 20 Hz with the thermistor's noise, in blocks of 7 rows: 0.18 of a step
/// RMS against the staircase's 0.21; from the rows' changes 0.038, as from the rows themselves).
/// Where the temperature turns inside one step, or holds between two, the line is off by less
/// than a step.
pub fn destep_temperature(t: &[f64], temp: &[f64], steps: &[ReadingSteps]) -> Option<Vec<f64>> {
    let n = temp.len().min(t.len()).min(steps.len());
    if n < 3 {
        return None;
    }
    let (held, changes) = steps[..n].iter().fold((0u64, 0u64), |(h, c), s| (h + s.held as u64, c + s.changes as u64));
    if (held as f64) < STEPPED_SHARE * (held + changes) as f64 {
        return None;
    }
    let points: Vec<(f64, f64)> = steps[..n]
        .iter()
        .filter(|s| s.changes > 0)
        .map(|s| (s.t_sum_s / s.changes as f64, s.value_sum_c / s.changes as f64))
        .collect();
    let mut out = temp[..n].to_vec();
    let mut j = 0;
    for k in 0..n {
        while j + 1 < points.len() && points[j + 1].0 <= t[k] {
            j += 1;
        }
        if let (Some(&(ta, va)), Some(&(tb, vb))) = (points.get(j), points.get(j + 1))
            && ta <= t[k]
            && tb > ta
        {
            out[k] = va + (vb - va) * (t[k] - ta) / (tb - ta);
        }
    }
    Some(out)
}

/// The temperature the thermal regressors are built from: `temp` smoothed over ±`half` rows,
/// so the thermistor's noise does not enter the regressors (errors in variables), without
/// rounding the turns of a ramp. A centred average over the window is used where a straight
/// line fits it; where it does not (a turn, a step) and a line through the rows on one side
/// only fits at least four times better, that one-sided line's value is used. A centred
/// average alone stays below the peak of a triangle by about the rate times half the window,
/// and a play started from that lower peak is offset for the whole next leg. Within `half` rows
/// of either end, where no centred window fits, the line through the rows the window reaches
/// is used: a window shrunk to the end row would pass its reading's noise whole, and a narrow
/// play would flicker on it.
pub fn smooth_temperature(t: &[f64], temp: &[f64], half: usize) -> Vec<f64> {
    let n = temp.len().min(t.len());
    let mut prefix = vec![0.0; n + 1];
    for k in 0..n {
        prefix[k + 1] = prefix[k] + temp[k];
    }
    (0..n)
        .map(|k| {
            let h = half.min(k).min(n - 1 - k);
            let mean = (prefix[k + h + 1] - prefix[k - h]) / (2 * h + 1) as f64;
            if h < half {
                // Within `half` of an end the centred window shrinks to the row itself: the line
                // through the rows the whole half-width reaches on the other side, at this row's
                // time, instead (unbiased on a ramp, and averaged as far as the window reaches).
                let (lo, hi) = (k.saturating_sub(half), (k + half).min(n - 1));
                return if hi - lo >= 2 { line_fit(t, temp, lo, hi, t[k]).1 } else { mean };
            }
            let (mse_c, _) = line_fit(t, temp, k - h, k + h, t[k]);
            let (mse_l, at_l) = line_fit(t, temp, k - h, k, t[k]);
            let (mse_r, at_r) = line_fit(t, temp, k, k + h, t[k]);
            let (mse_side, at_side) = if mse_l <= mse_r { (mse_l, at_l) } else { (mse_r, at_r) };
            if mse_side * 4.0 < mse_c { at_side } else { mean }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{ReadingSteps, destep_temperature, smooth_temperature};

    #[test]
    fn a_stepped_reading_is_taken_between_its_steps() {
        // A case warming toward 20 °C with a 650 s time constant from 0 °C, read to 1/16 °C at
        // 2 Hz for an hour: late in the hour a step every minute or more, far longer than the
        // ±10 s smoothing, and the staircase is off by up to half a step.
        let q = 0.0625;
        let t: Vec<f64> = (0..7200).map(|k| k as f64 * 0.5).collect();
        let truth: Vec<f64> = t.iter().map(|&x| 20.0 * (1.0 - (-x / 650.0).exp())).collect();
        let read: Vec<f64> = truth.iter().map(|v| (v / q).round() * q).collect();
        // Between the first minute and the last step (before the first step and after the last
        // the reading is all there is).
        let last = (1..7200).rfind(|&k| read[k] != read[k - 1]).expect("steps");
        let worst = |v: &[f64], from: usize| (from..last).map(|k| (v[k] - truth[k]).abs()).fold(0.0, f64::max);
        let staircase = smooth_temperature(&t, &read, 20);
        let between = destep_temperature(&t, &read, &ReadingSteps::of_rows(&t, &read)).expect("the reading is stepped");
        let smoothed = smooth_temperature(&t, &between, 20);
        assert!(worst(&staircase, 120) > 0.4 * q, "{}", worst(&staircase, 120));
        // Off by the curvature between steps alone: at most an eighth of a step, where the steps
        // are minutes apart.
        assert!(worst(&smoothed, 120) < 0.15 * q, "{}", worst(&smoothed, 120));
        let rms =
            |v: &[f64]| ((120..last).map(|k| (v[k] - truth[k]).powi(2)).sum::<f64>() / (last - 120) as f64).sqrt();
        assert!(rms(&smoothed) < 0.15 * rms(&staircase), "{} vs {}", rms(&smoothed), rms(&staircase));
        // A reading that changes every row is not stepped, whatever its resolution.
        let noisy: Vec<f64> = truth.iter().enumerate().map(|(k, v)| v + 1e-3 * ((k % 7) as f64 - 3.0)).collect();
        assert!(destep_temperature(&t, &noisy, &ReadingSteps::of_rows(&t, &noisy)).is_none());
        // A reading whose noise is a third of its step (1/128 °C read with 0.003 °C of noise)
        // is dithered, not stepped: its mean follows the temperature.
        let fine = 0.0078125;
        let dithered: Vec<f64> = truth
            .iter()
            .enumerate()
            .map(|(k, v)| ((v + 0.6 * fine * (((k * 7919) % 101) as f64 / 50.0 - 1.0)) / fine).round() * fine)
            .collect();
        assert!(destep_temperature(&t, &dithered, &ReadingSteps::of_rows(&t, &dithered)).is_none());
        // A hold at a step's edge, the reading flickering between two levels: the temperature
        // is the edge.
        let flicker: Vec<f64> = (0..7200).map(|k| if (k / 6) % 2 == 0 { 10.0 } else { 10.0 + q }).collect();
        let on_edge = destep_temperature(&t, &flicker, &ReadingSteps::of_rows(&t, &flicker)).expect("stepped");
        assert!((10..7190).all(|k| (on_edge[k] - (10.0 + 0.5 * q)).abs() < 1e-12));
    }

    #[test]
    fn a_stepped_reading_reduced_to_block_means_is_taken_between_its_steps() {
        // The same unit warming, read to 1/16 °C at 20 Hz with the thermistor's 0.003 °C of
        // noise (deterministic), then reduced to means over blocks of 7 rows as the diagnosis
        // does for a long record: a block that straddles a step holds a mean between the two
        // readings, and the noise flickers the reading across a step over several blocks.
        let q = 0.0625;
        let rows = 72_000;
        let b = 7;
        let t_row: Vec<f64> = (0..rows).map(|k| k as f64 * 0.05).collect();
        let truth_row: Vec<f64> = t_row.iter().map(|&x| 20.0 * (1.0 - (-x / 650.0).exp())).collect();
        let noise = |k: usize| 0.003 * (((k * 7919) % 101) as f64 / 50.0 - 1.0) * 1.7;
        let read_row: Vec<f64> = truth_row.iter().enumerate().map(|(k, v)| ((v + noise(k)) / q).round() * q).collect();
        let mean = |v: &[f64], j: usize| v[j * b..(j + 1) * b].iter().sum::<f64>() / b as f64;
        let blocks = rows / b;
        let t: Vec<f64> = (0..blocks).map(|j| mean(&t_row, j)).collect();
        let truth: Vec<f64> = (0..blocks).map(|j| mean(&truth_row, j)).collect();
        let read: Vec<f64> = (0..blocks).map(|j| mean(&read_row, j)).collect();
        let row_steps = ReadingSteps::of_rows(&t_row, &read_row);
        let steps: Vec<ReadingSteps> =
            (0..blocks).map(|j| ReadingSteps::total(&row_steps[j * b..(j + 1) * b])).collect();
        let last = (1..blocks).rfind(|&k| read[k] != read[k - 1]).expect("steps");
        let from = 120 * 20 / b;
        let rms =
            |v: &[f64]| ((from..last).map(|k| (v[k] - truth[k]).powi(2)).sum::<f64>() / (last - from) as f64).sqrt();
        let staircase = smooth_temperature(&t, &read, 29);
        let smoothed = smooth_temperature(&t, &destep_temperature(&t, &read, &steps).expect("stepped"), 29);
        // The line through the block means' own changes, as if each block were a row: half
        // the staircase is left.
        let own = smooth_temperature(
            &t,
            &destep_temperature(&t, &read, &ReadingSteps::of_rows(&t, &read)).expect("stepped"),
            29,
        );
        // The rows themselves, destepped and smoothed over the same ±10 s, then averaged over
        // the blocks: what the blocks can at best give.
        let by_rows =
            smooth_temperature(&t_row, &destep_temperature(&t_row, &read_row, &row_steps).expect("stepped"), 200);
        let by_rows: Vec<f64> = (0..blocks).map(|j| mean(&by_rows, j)).collect();
        assert!(rms(&staircase) > 0.2 * q, "{}", rms(&staircase));
        assert!(rms(&own) > 0.1 * q, "{}", rms(&own));
        assert!(rms(&smoothed) < 0.05 * q, "{} vs {} and {}", rms(&smoothed), rms(&own), rms(&staircase));
        assert!(rms(&smoothed) < 1.2 * rms(&by_rows), "{} vs {} from the rows", rms(&smoothed), rms(&by_rows));
    }

    #[test]
    fn smoothing_keeps_a_ramps_turn_and_averages_the_noise_on_a_leg() {
        // A triangle at 0.04 °C/s, 2 Hz, turning at 500 s, with ±0.003 °C of deterministic
        // pseudo-noise.
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.5).collect();
        let truth: Vec<f64> = t.iter().map(|&x| 20.0 + 0.04 * (500.0 - (x - 500.0).abs())).collect();
        let noise = |k: usize| 0.003 * (((k * 7919) % 101) as f64 / 50.0 - 1.0);
        let read: Vec<f64> = truth.iter().enumerate().map(|(k, v)| v + noise(k)).collect();
        let s = smooth_temperature(&t, &read, 20);
        // At the turn a centred ±10 s average is 0.1 °C low; the one-sided lines are not.
        let turn = 1000;
        assert!((s[turn] - truth[turn]).abs() < 0.005, "{} vs {}", s[turn], truth[turn]);
        let worst = (0..2000).map(|k| (s[k] - truth[k]).abs()).fold(0.0, f64::max);
        assert!(worst < 0.006, "worst {worst}");
        // On a straight leg the centred average is used: the noise shrinks.
        let rms = |v: &[f64], r: std::ops::Range<usize>| {
            (r.clone().map(|k| (v[k] - truth[k]).powi(2)).sum::<f64>() / r.len() as f64).sqrt()
        };
        assert!(rms(&s, 200..800) < 0.5 * rms(&read, 200..800), "{} vs {}", rms(&s, 200..800), rms(&read, 200..800));
    }
}
