//! Separability of two explanations on a design: the deviance a rival cannot absorb of what
//! another explanation predicts (the T-criterion of Atkinson & Fedorov, 1975).
//!
//! An explanation A (a set of fitted mechanisms) predicts `η_A` on a design (the rows,
//! temperatures, power-ons and positions of a recording, or of a test not yet run). A rival B is
//! refitted to `η_A` — its coefficients by generalised least squares under the noise model, its
//! θ searched on its grid and refined — with the columns both explanations share (the nuisance
//! and the other members) free beside it. What B cannot absorb, in the whitened metric and in
//! units of the residual variance (times the autocorrelation inflation), is the expected
//! likelihood-ratio statistic of A against B were A true: the deviance the design lets the data
//! show between them. Below the naming threshold, data drawn from A would seldom name A over B,
//! and the two are one ambiguous group whatever one recording's ranking says. Holding B at
//! fixed values instead of refitting it overstates the separation.
//!
//! The design is a [`Context`] (built from a [`super::prep::Prepared`]), so a design other than
//! the recording's can be passed.

use super::fit::PartialLs;
use super::mech::{Context, Mech};
use super::noise::Filter;

/// One fitted member of an explanation: the mechanism, its θ and the coefficients of its raw
/// columns ([`Context::columns`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Fitted {
    /// The mechanism.
    pub mech: Mech,
    /// Its time constant \[s\] or width [°C].
    pub theta: Option<f64>,
    /// Coefficients of its columns.
    pub coef: Vec<f64>,
}

/// What a rival absorbs of an explanation's prediction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Separation {
    /// The deviance the rival cannot absorb (expected likelihood-ratio statistic of the
    /// explanation against the refitted rival).
    pub deviance: f64,
    /// The rival's θ at its best (for mechanisms with one).
    pub rival_theta: Option<f64>,
}

/// A fitted term's contribution changed: its columns built otherwise (`cols`, at another
/// temperature or state) at its coefficients `coef`, less its `contribution` \[g\].
fn change_of(cols: &[Vec<f64>], coef: &[f64], contribution: &[f64]) -> Vec<f64> {
    let mut d: Vec<f64> = contribution.iter().map(|v| -v).collect();
    for (c, b) in cols.iter().zip(coef) {
        for (x, v) in d.iter_mut().zip(c) {
            *x += b * v;
        }
    }
    d
}

/// A lag's state at θ with the die's rise it misses at each power-on (`te − ρ·e^(−P/θ)`,
/// [`Context::with_missed_rise`]), and the same with that rise 1 °C larger.
fn lag_states(ctx: &Context, theta: f64, power: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let te = ctx.with_missed_rise(
        Mech::ThermalLag,
        theta,
        super::mech::state_of(Mech::ThermalLag, &ctx.p.t, &ctx.p.temp_s, theta),
    );
    let raised = te.iter().zip(power).map(|(x, pw)| x - (-pw / theta).exp()).collect();
    (te, raised)
}

/// The columns of the temperature form `rival` (θ `theta` for a play) built from the die's
/// temperature `die` instead of the thermistor's. For the bias polynomial, the orders SIM's
/// calibration holds are shared at the thermistor's temperature: the rival adds their
/// difference at the die's.
fn form_at_die(ctx: &Context, rival: Mech, theta: f64, die: &[f64]) -> Vec<Vec<f64>> {
    let mut cols = ctx.columns_at(rival, theta, die);
    if rival == Mech::BiasTempOrder {
        let at_die = super::mech::bias_powers(die, &ctx.nuisance_orders);
        let at_thermistor = super::mech::bias_powers(&ctx.p.temp_s, &ctx.nuisance_orders);
        cols.extend(at_die.iter().zip(&at_thermistor).map(|(d, t)| d.iter().zip(t).map(|(a, b)| a - b).collect()));
    }
    cols
}

/// The tempcos SIM may lack that a play's rivals act through: built from a die that lags the
/// thermistor ([`Refit::through_die_lag`]), or read at a play's state
/// ([`Refit::play_through_fitted_tempco`]).
pub(crate) const TEMPCO_FORMS: [Mech; 3] = [Mech::BiasTempOrder, Mech::ScaleTemp, Mech::CrossCouplingTemp];

/// Whether the specific force's component `j` changes over the recording (by more than 0.1 g):
/// a term in `f_j` is then a column of its own, not a constant.
fn force_moves(p: &super::prep::Prepared, j: usize) -> bool {
    p.f.iter().any(|f| (f[j] - p.f[0][j]).abs() > 0.1)
}

/// The prediction of `members` on the design `ctx` \[g\].
pub fn predict(ctx: &Context, members: &[Fitted]) -> Vec<f64> {
    let n = ctx.p.t.len();
    let mut eta = vec![0.0; n];
    for m in members {
        let cols = ctx.columns(m.mech, m.theta.unwrap_or(0.0));
        for (c, b) in cols.iter().zip(&m.coef) {
            for (e, v) in eta.iter_mut().zip(c) {
                *e += b * v;
            }
        }
    }
    eta
}

/// What a rival is refitted against: the prediction of an explanation on a design, whitened
/// once under the noise model with the columns both explanations share; each rival's columns
/// are then whitened and solved beside them ([`Refit::deviance`]).
pub struct Refit<'c, 'p> {
    ctx: &'c Context<'p>,
    filt: Filter,
    part: PartialLs,
    scale: f64,
}

impl<'c, 'p> Refit<'c, 'p> {
    /// The refit of rivals to `eta` (an explanation's prediction on the design `ctx`,
    /// [`predict`]) with the columns `shared` free in both, under the noise model of random-walk
    /// intensity `q` [g²/s]; `scale` is the residual variance of the whitened innovations times
    /// the autocorrelation inflation (the deviance's unit,
    /// [`super::fit::AxisFit::deviance_scale`]).
    pub fn new(ctx: &'c Context<'p>, q: f64, scale: f64, eta: &[f64], shared: &[Vec<f64>]) -> Self {
        let filt = Filter::new(&ctx.p.t, &ctx.p.r_white[ctx.axis], q, ctx.gm, |_| true);
        let part = PartialLs::new(&filt, eta, shared);
        Refit { ctx, filt, part, scale: scale.max(1e-300) }
    }

    /// The whitened residual sum of squares with the rival's columns `cols` beside the shared
    /// ones; where this design makes some of them collinear (a cross-sensitivity tempco's
    /// `f_j ΔT` and `f_k ΔT` in one orientation), the best of the subsets that are not;
    /// infinite for no column at all.
    fn sse(&self, cols: &[Vec<f64>]) -> f64 {
        if cols.iter().all(|c| c.iter().all(|v| *v == 0.0)) {
            return f64::INFINITY;
        }
        let sse = self.part.sse_plus(&self.filt, cols);
        if sse.is_finite() || cols.len() < 2 {
            return sse;
        }
        (1u32..(1 << cols.len()) - 1)
            .map(|mask| {
                let sub: Vec<Vec<f64>> =
                    cols.iter().enumerate().filter(|(j, _)| mask >> j & 1 == 1).map(|(_, c)| c.clone()).collect();
                self.part.sse_plus(&self.filt, &sub)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The deviance the rival given by its columns at θ (`columns(θ)`) cannot absorb, θ
    /// searched on `grid` where `offered` and refined by golden section in ln θ within the
    /// grid's span (a rival without θ: `grid` empty, `columns` called once with 0). `None` when
    /// the rival has no column on this design.
    pub fn deviance(
        &self,
        grid: &[f64],
        offered: &dyn Fn(f64) -> bool,
        columns: &dyn Fn(f64) -> Vec<Vec<f64>>,
    ) -> Option<Separation> {
        let sse_at = |theta: f64| self.sse(&columns(theta));
        if grid.is_empty() {
            let sse = sse_at(0.0);
            return sse.is_finite().then_some(Separation { deviance: sse / self.scale, rival_theta: None });
        }
        let mut best: Option<(f64, f64)> = None;
        for &th in grid {
            let s = sse_at(th);
            if s.is_finite() && best.is_none_or(|b| s < b.1) {
                best = Some((th, s));
            }
        }
        let (th0, s0) = best?;
        // Within the grid's span: a play wider than the grid's never engages over the
        // temperatures swept (a polynomial in T under another name, not a rival play).
        let step = if grid.len() > 1 { (grid[1] / grid[0]).ln() } else { 0.3 };
        let (g_lo, g_hi) = (grid[0].ln(), grid[grid.len() - 1].ln());
        let eval = |lt: f64| if offered(lt.exp()) { sse_at(lt.exp()) } else { f64::INFINITY };
        let (lo, hi) = ((th0.ln() - step).max(g_lo), (th0.ln() + step).min(g_hi));
        let (lt, s) = super::stats::golden_min(lo, hi, 12, eval);
        let (th, s) = if s < s0 { (lt.exp(), s) } else { (th0, s0) };
        Some(Separation { deviance: s / self.scale, rival_theta: Some(th) })
    }

    /// The rival's curve as the refit makes it: `cols` beside `shared` (the raw columns this
    /// refit was made with, in the same order) at their generalised-least-squares coefficients
    /// under the noise model, summed \[g\]; `None` when they are collinear.
    pub fn fitted(&self, shared: &[Vec<f64>], cols: &[Vec<f64>]) -> Option<Vec<f64>> {
        let coef = self.part.coef_plus(&self.filt, cols)?;
        let mut out = vec![0.0; self.ctx.p.t.len()];
        for (c, b) in shared.iter().chain(cols).zip(&coef) {
            for (o, v) in out.iter_mut().zip(c) {
                *o += b * v;
            }
        }
        Some(out)
    }

    /// The library's mechanism `rival` as this refit fits it: θ where it absorbs most (as
    /// [`Refit::mechanism`] searches it) and its coefficients beside the shared columns by
    /// generalised least squares. Refitted to a recording's data, it is the rival's own
    /// explanation of that recording, which [`predict`] carries to another design.
    pub fn fitted_mechanism(&self, rival: Mech) -> Option<Fitted> {
        let sep = self.mechanism(rival)?;
        let cols = self.ctx.columns(rival, sep.rival_theta.unwrap_or(0.0));
        let coef = self.part.coef_plus(&self.filt, &cols)?;
        let own = coef[coef.len().checked_sub(cols.len())?..].to_vec();
        Some(Fitted { mech: rival, theta: sep.rival_theta, coef: own })
    }

    /// The deviance the library's mechanism `rival` cannot absorb (θ searched on its grid where
    /// it has one).
    pub fn mechanism(&self, rival: Mech) -> Option<Separation> {
        let ctx = self.ctx;
        let grid: Vec<f64> = if rival.theta().is_some() {
            ctx.grid(rival).into_iter().filter(|&th| ctx.offered(rival, th)).collect()
        } else {
            Vec::new()
        };
        if rival.theta().is_some() && grid.is_empty() {
            return None;
        }
        self.deviance(&grid, &|th| ctx.offered(rival, th), &|th| ctx.columns(rival, th))
    }

    /// The deviance the temperature form `rival` cannot absorb acting on a die that self-heats
    /// after each power-on, unseen by the thermistor: its columns built from
    /// `T + ρ·(1 − e^(−P/τ))` (ρ = 0.3, 1 and [`DIE_RISE_MAX_C`] °C; a play's width 0.1–3 °C; τ
    /// on the turn-on grid; then the best width and ρ each refined by a factor of 0.5–2, ρ not
    /// beyond [`DIE_RISE_MAX_C`], and τ refined as [`Refit::deviance`] refines any rival's θ).
    /// On a soak after a power-on a tempco acting through the die's rise is a turn-on
    /// transient; over a wide temperature range the same coefficients must also fit the ramps,
    /// and then it is not. The bias polynomial takes all three orders, also
    /// those SIM's calibration of this recording holds ([`super::mech::sim_fitted_forms`]):
    /// that calibration fitted them at the thermistor's temperature, and the die's rise is what
    /// it left. Where the thermistor itself reads nothing but a rise after each power-on
    /// ([`soak_rise`]), the die's temperature is also tried as that rise alone at a τ of its own,
    /// `T₀ + A·(1 − e^(−P/τ))`: the thermistor's reading is then no better a record of the die's
    /// path than its own start and rise, and a coarse reading's steps are not the die's.
    pub fn through_die_rise(&self, rival: Mech) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let taus: Vec<f64> = ctx.grid(Mech::Warmup);
        if taus.is_empty() || !rival.temperature_form() || !ctx.rival_possible(rival) {
            return None;
        }
        let thetas: Vec<f64> = match rival {
            Mech::ThermalHysteresis | Mech::BiasHysteresis => vec![0.1, 0.3, 1.0, 3.0],
            Mech::ThermalLag => return None,
            _ => vec![0.0],
        };
        let soak = soak_rise(ctx);
        // ρ > 0: the thermistor's reading plus a rise of ρ; ρ = 0: the soak's rise alone.
        let columns = |rho: f64, th: f64, tau: f64| -> Vec<Vec<f64>> {
            let temp = match &soak {
                Some(sessions) if rho == 0.0 => soak_temperature(sessions, power, tau),
                _ => super::mech::die_temperature(&ctx.p.temp_s, power, rho, tau),
            };
            form_at_die(ctx, rival, th, &temp)
        };
        // The best (SSE, ρ, width) over τ on the turn-on grid, kept in `at`.
        let mut at: Option<(f64, f64, f64)> = None;
        let try_at = |at: &mut Option<(f64, f64, f64)>, rho: f64, th: f64| {
            for &tau in &taus {
                let s = self.sse(&columns(rho, th, tau));
                if s.is_finite() && at.is_none_or(|b| s < b.0) {
                    *at = Some((s, rho, th));
                }
            }
        };
        // The grid over (ρ, width); then the width and ρ, one after the other, about its best
        // (each by a factor of 2 either way at most, ρ not beyond DIE_RISE_MAX_C): a play
        // engages where the die has moved half its width, and a width or rise a step of the
        // grid off puts the engagement in the wrong part of the warm-up. τ is refined last.
        let rhos: &[f64] = if soak.is_some() { &[0.0, 0.3, 1.0, DIE_RISE_MAX_C] } else { &[0.3, 1.0, DIE_RISE_MAX_C] };
        for &rho in rhos {
            for &th in &thetas {
                try_at(&mut at, rho, th);
            }
        }
        let (_, rho, th) = at?;
        if thetas.len() > 1 {
            for k in REFINE_FACTORS {
                try_at(&mut at, rho, th * k);
            }
        }
        let (_, rho, th) = at?;
        if rho > 0.0 {
            for k in REFINE_FACTORS.into_iter().filter(|k| rho * k <= DIE_RISE_MAX_C) {
                try_at(&mut at, rho * k, th);
            }
        }
        let (_, rho, th) = at?;
        let best = self
            .deviance(&taus, &|tau| ctx.offered(Mech::Warmup, tau), &|tau| columns(rho, th, tau))
            .map_or(f64::INFINITY, |s| s.deviance);
        best.is_finite().then_some(best)
    }
}

impl Refit<'_, '_> {
    /// The deviance a fitted term (`mech` at `theta` with coefficients `coef`, contributing
    /// `contribution` at the recording's temperatures) cannot absorb acting on a die that
    /// self-heats after each power-on unseen by the thermistor: the rival column is the term's
    /// contribution at `T + ρ·(1 − e^(−P/τ))` less its contribution at `T` (τ on the turn-on
    /// grid; ρ = 1 °C for a lag, which is linear in `T`, and 0.3, 1 and [`DIE_RISE_MAX_C`] °C for
    /// a play, which is not). A lag or a play of the die's own rise is a transient after each
    /// power-on that a turn-on term, a drift or another play would otherwise take; the term's
    /// own columns are among the shared ones, so only the transient is new.
    pub fn fitted_through_die_rise(
        &self,
        mech: Mech,
        theta: Option<f64>,
        coef: &[f64],
        contribution: &[f64],
    ) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let grid = ctx.grid(Mech::Warmup);
        if grid.is_empty() || !mech.temperature_form() {
            return None;
        }
        let rhos: &[f64] = match mech {
            Mech::ThermalHysteresis | Mech::BiasHysteresis => &[0.3, 1.0, DIE_RISE_MAX_C],
            _ => &[1.0],
        };
        let mut best: Option<f64> = None;
        for &rho in rhos {
            let columns = |tau: f64| -> Vec<Vec<f64>> {
                let temp = super::mech::die_temperature(&ctx.p.temp_s, power, rho, tau);
                vec![change_of(&ctx.columns_at(mech, theta.unwrap_or(0.0), &temp), coef, contribution)]
            };
            if let Some(s) = self.deviance(&grid, &|th| ctx.offered(Mech::Warmup, th), &columns)
                && best.is_none_or(|b| s.deviance < b)
            {
                best = Some(s.deviance);
            }
        }
        best
    }

    /// The deviance a fitted thermal lag (at `theta`, coefficients `coef`, contributing
    /// `contribution`) cannot absorb with the die's rise it misses at each power-on at another
    /// size ([`Context::with_missed_rise`]: the state `te − ρ·e^(−P/θ)`, ρ one estimate for the
    /// unit from a grid, or none): the rival column is the lag's contribution with `ρ + 1 °C`
    /// less its contribution, its size free. A turn-on term beside the lag at about the lag's
    /// time constant is that rise resized as much as a term of its own. `None` without
    /// `power_s` or where no power-on is within the lag's reach.
    pub fn lag_rise_resized(&self, theta: f64, coef: &[f64], contribution: &[f64]) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let temp = &ctx.p.temp_s;
        let (_, raised) = lag_states(ctx, theta, power);
        let d = change_of(&ctx.state_columns(Mech::ThermalLag, theta, &raised, temp), coef, contribution);
        let size = contribution.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if !(d.iter().fold(0.0f64, |m, v| m.max(v.abs())) > 1e-9 * size) {
            return None;
        }
        self.deviance(&[], &|_| true, &|_| vec![d.clone()]).map(|s| s.deviance)
    }

    /// The deviance a die lag cannot absorb with its missed rise at power-on of any size: the
    /// lag's column at θ ([`Context::with_missed_rise`]) beside the change of that column with
    /// the rise 1 °C larger, both free, θ on the lag's grid. Refitted to what a turn-on term and
    /// a play or temperature form predict together, it is whether the pair is one lag the model
    /// lacks: on one ramp from a cold power-on the play takes the lag's offset along the ramp
    /// and the turn-on term the transient the thermistor misses. `None` without `power_s`.
    pub fn lag_with_rise_free(&self) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let temp = &ctx.p.temp_s;
        let grid = ctx.grid(Mech::ThermalLag);
        let columns = |th: f64| -> Vec<Vec<f64>> {
            let (te, raised) = lag_states(ctx, th, power);
            let mut cols = ctx.state_columns(Mech::ThermalLag, th, &te, temp);
            let c1 = ctx.state_columns(Mech::ThermalLag, th, &raised, temp);
            cols.push(c1[0].iter().zip(&cols[0]).map(|(a, b)| a - b).collect());
            cols
        };
        self.deviance(&grid, &|_| true, &columns).map(|s| s.deviance)
    }

    /// The deviance a richer form of the fitted lag or play `mech` cannot absorb: its columns
    /// at θ times `(1, ΔT, ΔT²)` (a gain that varies with temperature, as a sensitivity's slope
    /// at a die running warmer than the thermistor does), θ on its grid. Beside a lag or a play,
    /// a term that only takes the rest of that one's shape is not a finding of its own.
    pub fn gain_with_temperature(&self, mech: Mech) -> Option<f64> {
        let ctx = self.ctx;
        if !matches!(mech, Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis) {
            return None;
        }
        let dt: Vec<f64> = ctx.p.temp_s.iter().map(|t| t - super::mech::T0_C).collect();
        let grid = ctx.grid(mech);
        let columns = |th: f64| -> Vec<Vec<f64>> {
            let base = ctx.columns(mech, th);
            let mut out = Vec::new();
            for c in &base {
                for e in 0..3 {
                    out.push(c.iter().zip(&dt).map(|(v, d)| v * d.powi(e)).collect());
                }
            }
            out
        };
        self.deviance(&grid, &|_| true, &columns).map(|s| s.deviance)
    }

    /// The deviance a thermal lag of a die that lags its own heating after each power-on as
    /// well cannot absorb: the lag (τ on its grid) of the die's temperature
    /// `T + ρ·(1 − e^(−P/τᵣ))`, through SIM's sensitivity, the rise ρ (0.3, 1 and
    /// [`DIE_RISE_MAX_C`] °C) reached within the turn-on grid's shortest time constant τᵣ: SIM's
    /// die heats at once, REAL's follows the case and its own heating τ behind. After the only
    /// power-on, that is a transient of the lag's own τ, which a warm-up, a self-heating or a
    /// play the rise engages makes as well. `None` without `power_s`.
    pub fn lag_of_die_rise(&self) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let grid = ctx.grid(Mech::ThermalLag);
        let rise_tau_s = ctx.shortest_tau_s();
        [0.3, 1.0, DIE_RISE_MAX_C]
            .iter()
            .filter_map(|&rho| {
                let die = super::mech::die_temperature(&ctx.p.temp_s, power, rho, rise_tau_s);
                self.deviance(&grid, &|_| true, &|th| ctx.columns_at(Mech::ThermalLag, th, &die))
            })
            .map(|s| s.deviance)
            .min_by(f64::total_cmp)
    }

    /// The deviance the fitted lag or play `mech` cannot absorb restarted at each session's
    /// first temperature instead of carried through the unpowered gaps, θ on its grid (the
    /// library takes the temperature to have gone straight between the readings; a unit left to
    /// settle before its next power-on, or a chamber that turned back in the gap, is not that).
    /// `None` for one session.
    pub fn other_state_across_sessions(&self, mech: Mech) -> Option<f64> {
        let ctx = self.ctx;
        let p = ctx.p;
        if p.sessions().len() < 2 || !matches!(mech, Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis)
        {
            return None;
        }
        let grid = ctx.grid(mech);
        let columns = |th: f64| -> Vec<Vec<f64>> {
            let te = super::mech::by_session(p, |r| super::mech::state_of(mech, &p.t[r.clone()], &p.temp_s[r], th));
            ctx.state_columns(mech, th, &ctx.with_missed_rise(mech, th, te), &p.temp_s)
        };
        self.deviance(&grid, &|_| true, &columns).map(|s| s.deviance)
    }

    /// The deviance a die that runs steadily warmer than its thermistor cannot absorb: the
    /// library's self-heating settled (`S'(T, f)`, SIM's sensitivity's slope), which long after
    /// power-on is a temperature function like a tempco SIM lacks, and at steady temperatures
    /// in several positions a static scale and cross term. Where SIM shows no temperature
    /// sensitivity (the free form) and a rise may have settled before the first row (it starts
    /// at least five of the turn-on grid's shortest τ after power-on, or no turn-on τ is
    /// offered), the settled die acts through tempcos nothing on the record fixes: a static
    /// term `f_j` for each specific-force component that changes. `None` without `power_s`.
    pub fn self_heating_settled(&self) -> Option<f64> {
        let ctx = self.ctx;
        let p = ctx.p;
        p.power.as_ref()?;
        let settled_before = ctx.power_range_s.0 >= 5.0 * ctx.shortest_tau_s();
        let col = if !ctx.s.from_sim && (settled_before || ctx.grid(Mech::SelfHeating).is_empty()) {
            (0..3).filter(|&j| force_moves(p, j)).map(|j| p.f.iter().map(|f| f[j]).collect()).collect()
        } else {
            ctx.columns(Mech::SelfHeating, 1e-9)
        };
        self.deviance(&[], &|_| true, &|_| col.clone()).map(|s| s.deviance)
    }

    /// The deviance a second first-order stage of the lag `tau_s` cannot absorb (a lag of the
    /// lagged temperature, its own τ on the lag's grid, beside the first stage the shared
    /// columns hold): a sensing element two stages behind the thermistor leaves, after a
    /// first-order fit, a remainder at the ramps' starts and ends that a play or a turn-on term
    /// would take.
    pub fn second_lag_stage(&self, tau_s: f64) -> Option<f64> {
        let ctx = self.ctx;
        let p = ctx.p;
        let first = super::mech::lagged(&p.t, &p.temp_s, tau_s);
        let grid = ctx.grid(Mech::ThermalLag);
        self.deviance(&grid, &|_| true, &|th| ctx.columns_at(Mech::ThermalLag, th, &first)).map(|s| s.deviance)
    }

    /// The deviance the temperature form `rival` cannot absorb acting on a die that lags the
    /// thermistor: its columns built from the thermistor's reading lagged by τ on the lag's
    /// grid. SIM's own sensitivity acting through such a lag is the library's `thermal_lag`
    /// (and so are the bias orders SIM's calibration of this recording holds, which the
    /// polynomial leaves out); a tempco SIM lacks acting through it is not, and on one ramp
    /// from a hold its knee where the die starts to trail is the knee of a play that engages.
    /// Only a form the search offers on this design ([`Context::available`]): a scale tempco
    /// on a component of the specific force that never changes is a bias term, and through
    /// a lag that is SIM's own bias curve lagged again. `None` for a form that is not a
    /// temperature function, one the design does not offer, or a recording without a lag's
    /// grid.
    pub fn through_die_lag(&self, rival: Mech) -> Option<f64> {
        let ctx = self.ctx;
        let p = ctx.p;
        let grid = ctx.grid(Mech::ThermalLag);
        if grid.is_empty() || !TEMPCO_FORMS.contains(&rival) || !ctx.available(rival) {
            return None;
        }
        let columns = |tau: f64| ctx.columns_at(rival, 0.0, &super::mech::lagged(&p.t, &p.temp_s, tau));
        self.deviance(&grid, &|_| true, &columns).map(|s| s.deviance)
    }

    /// The deviance a thermal play cannot absorb acting through SIM's sensitivity and the
    /// fitted tempco `mech` beside it (coefficients `coef`, contributing `contribution`): the
    /// play's columns at width h on its grid and the tempco's contribution at the play's state
    /// less its contribution at the thermistor's temperature, each with a gain of its own. A
    /// sensor whose temperature follows the thermistor through a play reads every tempco it
    /// has at that state; where the recording shows a tempco SIM lacks, the play through it is
    /// a difference between the heating and cooling legs that SIM's sensitivity does not
    /// predict, which is what an additive play is. `None` for a term that is not a tempco or
    /// a recording without a play's grid.
    pub fn play_through_fitted_tempco(&self, mech: Mech, coef: &[f64], contribution: &[f64]) -> Option<f64> {
        let ctx = self.ctx;
        let grid = ctx.grid(Mech::ThermalHysteresis);
        if grid.is_empty() || !TEMPCO_FORMS.contains(&mech) {
            return None;
        }
        let columns = |h: f64| -> Vec<Vec<f64>> {
            let state = super::mech::play(&ctx.p.temp_s, h);
            let mut cols = ctx.columns_at(Mech::ThermalHysteresis, h, &ctx.p.temp_s);
            cols.push(change_of(&ctx.columns_at(mech, 0.0, &state), coef, contribution));
            // SIM without a temperature sensitivity gives the play no column of its own.
            cols.retain(|c| c.iter().any(|v| *v != 0.0));
            cols
        };
        self.deviance(&grid, &|_| true, &columns).map(|s| s.deviance)
    }

    /// The deviance a die heating after power-on cannot absorb, acting through a sensitivity
    /// of its own: `(1 − e^(−P/τ))·(c0 + c1 ΔT + c2 ΔT²)`, τ on the turn-on grid (the library's
    /// self-heating with SIM's sensitivity replaced by a free quadratic). `None` without
    /// `power_s` or a turn-on τ the recording shows.
    pub fn self_heating_free(&self) -> Option<f64> {
        let ctx = self.ctx;
        let power = ctx.p.power.as_deref()?;
        let grid = ctx.grid(Mech::SelfHeating);
        if grid.is_empty() {
            return None;
        }
        let dt: Vec<f64> = ctx.p.temp_s.iter().map(|t| t - super::mech::T0_C).collect();
        let columns = |tau: f64| -> Vec<Vec<f64>> {
            let rise: Vec<f64> = power.iter().map(|p| -(-p / tau).exp_m1()).collect();
            (0..3).map(|e| rise.iter().zip(&dt).map(|(r, d)| r * d.powi(e)).collect()).collect()
        };
        self.deviance(&grid, &|th| ctx.offered(Mech::SelfHeating, th), &columns).map(|s| s.deviance)
    }

    /// The deviance a die heating after power-on cannot absorb acting through the scale factor
    /// and cross-sensitivities' own tempcos: `(1 − e^(−P/τ))·f_j` for each specific-force
    /// component, τ on the turn-on grid. Once the die has settled this is a static scale term,
    /// and over a soak a scale-factor tempco is one too (the temperature moves only with the
    /// die's rise): only the transient after each power-on tells them apart. `None` without
    /// `power_s`, a turn-on τ the recording shows, or a specific force that changes.
    pub fn self_heating_through_scale(&self) -> Option<f64> {
        self.scale_rise(false)
    }

    /// The deviance a static scale or cross term beside the die's rise after power-on through
    /// the same tempcos cannot absorb: `f_j` and `(1 − e^(−P/τ))·f_j` for each specific-force
    /// component that changes, τ on the turn-on grid. Over a soak the temperature moves only
    /// with the die's rise, so a scale-factor or cross-coupling tempco is that pair there: its
    /// level at the soak's temperature a static term, its change the rise. `None` as for
    /// [`Refit::self_heating_through_scale`].
    pub fn static_scale_with_self_heating(&self) -> Option<f64> {
        self.scale_rise(true)
    }

    /// The rise through the scale factor's and cross-sensitivities' tempcos,
    /// `(1 − e^(−P/τ))·f_j` for each component `j` of the specific force that changes, with
    /// `f_j` itself beside it where `with_static`.
    fn scale_rise(&self, with_static: bool) -> Option<f64> {
        let ctx = self.ctx;
        let p = ctx.p;
        let power = p.power.as_deref()?;
        let grid = ctx.grid(Mech::SelfHeating);
        let moves = |j: usize| force_moves(p, j);
        if grid.is_empty() || !(0..3).any(moves) {
            return None;
        }
        let columns = |tau: f64| -> Vec<Vec<f64>> {
            let mut cols = Vec::new();
            for j in (0..3).filter(|&j| moves(j)) {
                if with_static {
                    cols.push(p.f.iter().map(|f| f[j]).collect());
                }
                cols.push(power.iter().zip(&p.f).map(|(pw, f)| -(-pw / tau).exp_m1() * f[j]).collect());
            }
            cols
        };
        self.deviance(&grid, &|th| ctx.offered(Mech::SelfHeating, th), &columns).map(|s| s.deviance)
    }

    /// The self-heating rival of a term odd in the specific force: the smaller deviance of the
    /// die's rise through the scale factor's and cross-sensitivities' tempcos
    /// ([`Refit::self_heating_through_scale`]) and of the die settled warmer than the
    /// thermistor ([`Refit::self_heating_settled`]), which long after power-on is that term.
    pub fn self_heating_of_scale_term(&self) -> Option<f64> {
        [self.self_heating_through_scale(), self.self_heating_settled()].into_iter().flatten().reduce(f64::min)
    }

    /// The deviance a thermal play wider than every temperature the recording swept cannot
    /// absorb: the sensor held at each session's starting temperature while the thermistor
    /// moves, `S(T_start, f) − S(T, f)` (the library's play at a width of twice the swept range
    /// and 1 °C more). Such a play never engages, and on this recording it is a temperature
    /// function with SIM's own shape, as a tempco or a die the sensor does not follow is. The
    /// search's grid stops at widths that engage, so only this rival says so. `None` where that
    /// width exceeds [`NEVER_ENGAGED_MAX_WIDTH_C`]: a recording that swept more would have
    /// engaged a play of a few °C, and the search's own widths answer it.
    pub fn play_never_engaged(&self) -> Option<f64> {
        let ctx = self.ctx;
        let width_c = 2.0 * ctx.temp_range + 1.0;
        if width_c > NEVER_ENGAGED_MAX_WIDTH_C {
            return None;
        }
        let cols = ctx.columns(Mech::ThermalHysteresis, width_c);
        self.deviance(&[], &|_| true, &|_| cols.clone()).map(|s| s.deviance)
    }
}

/// The widest play [`Refit::play_never_engaged`] stands for \[°C\]: a thermal backlash of a
/// few °C, which a recording that swept (8 − 1) / 2 = 3.5 °C or more would have engaged. Over a
/// wider sweep a play that never engages would have to be wider than any thermal play, and a
/// temperature function with SIM's shape there is a tempco.
pub const NEVER_ENGAGED_MAX_WIDTH_C: f64 = 8.0;

/// Largest RMS \[°C\] by which the thermistor's smoothed reading may depart from its start plus
/// one rise after power-on for [`soak_rise`] to take the session as a soak (or the reading's
/// resolution, where coarser).
pub const SOAK_FIT_C: f64 = 0.03;

/// Per session, the thermistor's smoothed reading as its start and one rise after power-on,
/// `T₀ + A·(1 − e^(−P/τ))` (least squares, τ on the turn-on grid): `(rows, T₀, A)` when every
/// session's reading is that to within [`SOAK_FIT_C`] RMS or the reading's resolution, so the
/// case held still and the temperature moved only with the unit's own rise; `None` otherwise
/// (a ramp, a step of the chamber, no `power_s`).
pub fn soak_rise(ctx: &Context) -> Option<Vec<(std::ops::Range<usize>, f64, f64)>> {
    let p = ctx.p;
    let power = p.power.as_deref()?;
    let taus = ctx.grid(Mech::Warmup);
    let tol = SOAK_FIT_C.max(p.temp_resolution_c.unwrap_or(0.0));
    let mut out = Vec::new();
    for r in p.sessions() {
        let temp = &p.temp_s[r.clone()];
        let n = temp.len() as f64;
        let mut best: Option<(f64, f64, f64)> = None;
        for &tau in &taus {
            let g: Vec<f64> = power[r.clone()].iter().map(|pw| -(-pw / tau).exp_m1()).collect();
            let (gm, tm) = (g.iter().sum::<f64>() / n, temp.iter().sum::<f64>() / n);
            let sgg: f64 = g.iter().map(|v| (v - gm).powi(2)).sum();
            let sgt: f64 = g.iter().zip(temp).map(|(v, t)| (v - gm) * (t - tm)).sum();
            let a = if sgg > 0.0 { sgt / sgg } else { 0.0 };
            let t0 = tm - a * gm;
            let rms = (g.iter().zip(temp).map(|(v, t)| (t0 + a * v - t).powi(2)).sum::<f64>() / n).sqrt();
            if best.is_none_or(|b| rms < b.0) {
                best = Some((rms, t0, a));
            }
        }
        let (rms, t0, a) = best?;
        if !(rms <= tol) {
            return None;
        }
        out.push((r, t0, a));
    }
    Some(out)
}

/// The die's temperature on a soak ([`soak_rise`]): each session's start plus its rise, at the
/// time constant `tau`.
fn soak_temperature(sessions: &[(std::ops::Range<usize>, f64, f64)], power: &[f64], tau: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(power.len());
    for (r, t0, a) in sessions {
        out.extend(power[r.clone()].iter().map(|pw| t0 - a * (-pw / tau).exp_m1()));
    }
    out
}

/// The deviance the rival `rival` (one mechanism, θ searched on its grid where it has one)
/// cannot absorb of what `a` predicts on the design `ctx`, with the columns `shared` free in
/// both explanations, under the noise model of random-walk intensity `q` [g²/s], in units of
/// `scale` ([`Refit::new`]). `None` when the rival has no column on this design.
pub fn separability(
    ctx: &Context,
    q: f64,
    scale: f64,
    a: &[Fitted],
    rival: Mech,
    shared: &[Vec<f64>],
) -> Option<Separation> {
    Refit::new(ctx, q, scale, &predict(ctx, a), shared).mechanism(rival)
}

/// The largest rise of the die over the thermistor after power-on that a rival may assume
/// [°C] ([`Refit::through_die_rise`]).
pub const DIE_RISE_MAX_C: f64 = 3.0;

/// The factors [`Refit::through_die_rise`] tries on its grid's best play width and rise ρ.
const REFINE_FACTORS: [f64; 6] = [0.5, 0.7, 0.85, 1.2, 1.4, 2.0];

/// The separation a name needs from a rival: the expected deviance `T` at which data drawn from
/// the named explanation exceed the naming threshold `thr` with 95 % probability (the
/// likelihood-ratio statistic is then about a noncentral χ² of `df` degrees of freedom and
/// noncentrality `T`: mean `df + T`, variance `2(df + 2T)`). Below it a recording of this design
/// names the wrong one of the two too often, and they are one group.
pub fn separation_needed(thr: f64, df: usize) -> f64 {
    let k = df.max(1) as f64;
    let power_ok = |t: f64| k + t - 1.645 * (2.0 * (k + 2.0 * t)).sqrt() >= thr;
    let (mut lo, mut hi) = (0.0, thr.max(1.0) * 4.0 + 100.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if power_ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}
