//! The simulator's rig program beyond the fixed plans: every shipped scenario's recording
//! pinned by its hash (what older scenarios produce does not change), a soak at its own ramp
//! rate, and a power cycle whose self-heating and warm-up restart as the documented thermal
//! model says, computed here independently in closed form.

use bins_cal::recording::{Row, Writer};
use bins_cal::sim::{Simulation, scenario};
use std::io::Write;
use std::path::{Path, PathBuf};

fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios").join(name)
}

/// FNV-1a, 64 bit: a stable hash written out here, so the pins do not depend on a library.
struct Fnv(u64, u64);

impl Write for Fnv {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        for &b in buf {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        self.1 += buf.len() as u64;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The bytes `bins-cal simulate` writes for `sim` and `seed` after its first two comment lines
/// (which carry the tool's version): the scenario's comments, the header and every row up to
/// `max_rows`, hashed; and the row count.
fn recording_hash(sim: &Simulation, seed: u64, max_rows: u64) -> (u64, u64, u64) {
    let refs: Vec<&str> = sim.comments.iter().map(String::as_str).collect();
    let mut w = Writer::new(Fnv(0xcbf2_9ce4_8422_2325, 0), "hash", sim.columns(), &refs).unwrap();
    let mut rows = sim.rows(seed);
    let mut row = Row::default();
    let mut n = 0u64;
    while n < max_rows && rows.next_row(&mut row) {
        w.write_row(&row).unwrap();
        n += 1;
    }
    let h = w.finish().unwrap();
    (h.0, h.1, n)
}

/// Hash, bytes and rows of the recording of each shipped scenario with seed 1, computed with
/// the simulator before the steps `power` and `soak.rate_C_per_min` existed (`power-cycle.toml`,
/// which uses them, since it was added). The two day-long
/// scenarios are pinned on their first 1 500 000 rows in the default run
/// (`shipped_scenarios_whole_days_are_unchanged` checks them whole, `--ignored`).
const PINNED: [(&str, u64, u64, u64); 17] = [
    ("day-100hz-sim.toml", 0xfe89281c5f426ff6, 160421716, 1500000),
    ("day-100hz.toml", 0x258f623b4d8ccd63, 160422614, 1500000),
    ("diagnose-ramps.toml", 0x4ff0bfcaf49ae564, 1040410, 11550),
    ("dynamics-tilter.toml", 0xaa35574cdf0e5864, 5704343, 44990),
    ("flight.toml", 0xacf7a7faff5932c2, 13350232, 99900),
    ("hand-40.toml", 0xaf3b32a5a963c9d8, 1313691, 20500),
    ("paper-shaker.toml", 0x0f1b27063e3bd0f6, 17189470, 170000),
    ("paper-tilter.toml", 0x8be8bd02c27963ac, 46737263, 380950),
    ("paper-unit-shaker.toml", 0x8b7865be3a39c4cb, 17094747, 170000),
    ("power-cycle.toml", 0xc1a3c13a167e880a, 7823087, 82450),
    ("replay-10min.toml", 0x2c42a38e3d98a7a9, 68589691, 600000),
    ("replay-short.toml", 0x9525f9102009bc01, 463226, 4000),
    ("test-al15-tilter.toml", 0x019defae344a2b9a, 32582, 400),
    ("test-shaker.toml", 0x24b1bc4e95503f2c, 1813715, 18000),
    ("test-tilter-3t.toml", 0x9842a2e859a48c34, 478301, 4100),
    ("three-hour-real.toml", 0xe4a76089a2e7422d, 100372657, 1080000),
    ("three-hour-sim.toml", 0xd73706f26918a656, 100375373, 1080000),
];

/// Whole days: the same file as before, all 8 640 000 rows.
const DAYS_WHOLE: [(&str, u64, u64, u64); 2] = [
    ("day-100hz-sim.toml", 0xd0d50e51d61c7a9a, 1168049220, 8640000),
    ("day-100hz.toml", 0xc27654e96feb9f0a, 1168045021, 8640000),
];

const DAY_PREFIX_ROWS: u64 = 1_500_000;

fn check_pins(pins: &[(&str, u64, u64, u64)], cap: impl Fn(&str) -> u64) {
    // Every shipped scenario is pinned.
    let mut shipped: Vec<String> = std::fs::read_dir(scenario_path(""))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    shipped.sort();
    if pins.len() == PINNED.len() {
        assert_eq!(shipped, pins.iter().map(|p| p.0.to_string()).collect::<Vec<_>>(), "scenarios/ changed");
    }
    let mut bad = Vec::new();
    for &(name, hash, bytes, rows) in pins {
        let sim = scenario::load(&scenario_path(name)).unwrap_or_else(|e| panic!("{e}"));
        let got = recording_hash(&sim, 1, cap(name));
        if got != (hash, bytes, rows) {
            bad.push(format!("    (\"{name}\", {:#018x}, {}, {}),", got.0, got.1, got.2));
        }
    }
    assert!(bad.is_empty(), "recordings differ from their pins; now:\n{}", bad.join("\n"));
}

#[test]
fn shipped_scenarios_give_the_same_recordings_as_before() {
    check_pins(&PINNED, |name| if name.starts_with("day-") { DAY_PREFIX_ROWS } else { u64::MAX });
}

#[test]
#[ignore = "two 24-hour recordings at 100 Hz: about 10 s in release"]
fn shipped_scenarios_whole_days_are_unchanged() {
    check_pins(&DAYS_WHOLE, |_| u64::MAX);
}

fn load(dir: &Path, name: &str, text: &str) -> Simulation {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    scenario::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

fn all_rows(sim: &Simulation) -> Vec<Row> {
    let mut rows = sim.rows(1);
    let mut row = Row::default();
    let mut out = Vec::new();
    while rows.next_row(&mut row) {
        out.push(row.clone());
    }
    out
}

/// A unit without temperature dependence (K = I, U0 below), its die 120 s behind the case and
/// heated 4 °C above it when powered, the thermistor at the die without a lag (`temp_C` is the
/// die), the case without a lag (it is the chamber), no noise: the signals are `f + U0` plus
/// the warm-up, `temp_C − chamber_C` is the die's self-heating.
const POWER_UNIT: &str = r#"
[recording]
rate_Hz = 10.0
power_on_s = 0.0
[unit]
t0_C = 20.0
k_V_per_g = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
u0_V = [0.01, -0.02, 0.03]
warmup_V = [2.0e-3, -1.0e-3, 5.0e-4]
warmup_tau_s = 60.0
[thermal]
start_C = 20.0
die_tau_s = 120.0
self_heating_C = 4.0
thermistor_at = 1.0
[[step]]
kind = "hold"
position = "TP1"
dwell_s = 600.0
"#;

const U0_V: [f64; 3] = [0.01, -0.02, 0.03];
const WARMUP_V: [f64; 3] = [2.0e-3, -1.0e-3, 5.0e-4];
const TAU_W_S: f64 = 60.0;
const TAU_DIE_S: f64 = 120.0;
const SH_C: f64 = 4.0;

#[test]
fn a_power_cycle_restarts_power_s_the_warm_up_and_the_self_heating() {
    // On 600 s from power-on, off 120 s with the chamber holding at 20 °C, on 900 s.
    let text = format!(
        "{POWER_UNIT}[[step]]\nkind = \"power\"\noff_s = 120.0\n[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 900.0\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "cycle.toml", &text);
    let rows = all_rows(&sim);
    // No rows while off: 6000 before, 9000 after, and the count the simulation announces.
    assert_eq!(rows.len(), 15_000);
    assert_eq!(sim.n_rows(), 15_000);
    let split = rows.iter().position(|r| r.t_s > 600.0).unwrap();
    assert_eq!(split, 6000);
    assert_eq!((rows[split - 1].t_s, rows[split].t_s), (599.9, 720.0));
    // The die's excess over the case, closed form of the documented model: heating
    // SH·(1 − e^(−t/τ)) from power-on, decaying as e^(−t/τ) while off, then
    // SH + (ΔT_on − SH)·e^(−t_p/τ).
    let off_at = 600.0;
    let on_at = 720.0;
    let excess_off = SH_C * (1.0 - (-off_at / TAU_DIE_S).exp());
    let excess_on = excess_off * (-(on_at - off_at) / TAU_DIE_S).exp();
    let mut worst = (0.0f64, 0.0f64);
    for r in &rows {
        let (power_s, excess) = if r.t_s < off_at {
            (r.t_s, SH_C * (1.0 - (-r.t_s / TAU_DIE_S).exp()))
        } else {
            let tp = r.t_s - on_at;
            (tp, SH_C + (excess_on - SH_C) * (-tp / TAU_DIE_S).exp())
        };
        assert_eq!(r.chamber_c, Some(20.0));
        assert!((r.power_s.unwrap() - power_s).abs() < 1e-9, "t = {}: power_s {:?}", r.t_s, r.power_s);
        let e = r.temp_c - 20.0;
        assert!((e - excess).abs() < 1e-9, "t = {}: die {e} °C above the case, closed form {excess}", r.t_s);
        worst.0 = worst.0.max((e - excess).abs());
        // The warm-up restarts with power_s: U − (f + U0) = A·e^(−t_p/τ_w), f = TP1 = +1 g on z.
        for i in 0..3 {
            let static_v = U0_V[i] + if i == 2 { 1.0 } else { 0.0 };
            let w = WARMUP_V[i] * (-power_s / TAU_W_S).exp();
            let d = r.u_v[i] - static_v - w;
            assert!(d.abs() < 1e-12, "t = {}, axis {i}: warm-up off by {d} V", r.t_s);
            worst.1 = worst.1.max(d.abs());
        }
    }
    // The restart is visible: at the second power-on the die is 1.46 °C above the case (it was
    // 3.97 °C at turn-off), and the warm-up is back at its full amplitude.
    let first_on = &rows[split];
    assert_eq!(first_on.power_s, Some(0.0));
    assert!((first_on.temp_c - 20.0 - excess_on).abs() < 1e-9 && excess_on < 1.5 && excess_off > 3.9);
    assert!((first_on.u_v[0] - U0_V[0] - WARMUP_V[0]).abs() < 1e-12);
    println!(
        "power cycle: die {excess_off:.4} °C above the case at turn-off, {excess_on:.4} at power-on; \
         largest difference from the closed forms: die {:.1e} °C, warm-up {:.1e} V",
        worst.0, worst.1
    );
    // The diagnosis reads the two sides as two sessions.
    let prep = bins_cal::diagnose::prep::prepare(&rows, &rows, Path::new("sim.csv"), Path::new("real.csv")).unwrap();
    assert_eq!(prep.sessions(), vec![0..6000, 6000..15_000]);
}

#[test]
fn while_off_the_die_follows_the_chamber_and_the_ramp_goes_on() {
    // Off 600 s while the chamber moves 20 → 30 °C at 2 °C/min (reached 300 s after turn-off).
    let text = format!(
        "{POWER_UNIT}[[step]]\nkind = \"power\"\noff_s = 600.0\nchamber_C = 30.0\nrate_C_per_min = 2.0\n[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 600.0\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "ramp-off.toml", &text);
    let rows = all_rows(&sim);
    assert_eq!(rows.len(), 12_000);
    let (off_at, on_at, ramp_s, rate) = (600.0, 1200.0, 300.0, 2.0 / 60.0);
    let excess_on = SH_C * (1.0 - (-off_at / TAU_DIE_S).exp()) * (-(on_at - off_at) / TAU_DIE_S).exp();
    // The die's lag behind a ramp of the case that stopped `ramp_s` after it began, at power-on.
    let lag_on =
        rate * TAU_DIE_S * (1.0 - (-ramp_s / TAU_DIE_S).exp()) * (-(on_at - off_at - ramp_s) / TAU_DIE_S).exp();
    let mut worst = 0.0f64;
    for r in rows.iter().filter(|r| r.t_s >= on_at) {
        let tp = r.t_s - on_at;
        let decay = (-tp / TAU_DIE_S).exp();
        let want = 30.0 - lag_on * decay + SH_C + (excess_on - SH_C) * decay;
        assert_eq!(r.chamber_c, Some(30.0));
        // The simulator's case moves in steps of rate·Δt held over each sample period: within
        // rate·Δt = 0.0033 °C of the continuous ramp's response.
        assert!((r.temp_c - want).abs() < 0.004, "t = {}: {} vs {want}", r.t_s, r.temp_c);
        worst = worst.max((r.temp_c - want).abs());
    }
    println!(
        "ramp while off: die lag {lag_on:.4} °C at power-on, largest difference from the closed form {worst:.1e} °C"
    );
}

#[test]
fn a_soak_reaches_its_set_point_at_its_own_rate() {
    // [thermal] moves at 1 °C/min; the first soak at its own 0.25 °C/min, the second at the
    // default.
    let text = r#"
[recording]
rate_Hz = 1.0
[unit]
preset = "paper"
[thermal]
start_C = 20.0
rate_C_per_min = 1.0
[[step]]
kind = "soak"
chamber_C = 50.0
rate_C_per_min = 0.25
dwell_s = 9000.0
[[step]]
kind = "soak"
chamber_C = 20.0
dwell_s = 2400.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "rates.toml", text);
    let rows = all_rows(&sim);
    // Least-squares slope of chamber_C over the rows strictly inside a ramp.
    let slope = |rows: &[&Row]| {
        let n = rows.len() as f64;
        let mt = rows.iter().map(|r| r.t_s).sum::<f64>() / n;
        let mc = rows.iter().map(|r| r.chamber_c.unwrap()).sum::<f64>() / n;
        let sxy: f64 = rows.iter().map(|r| (r.t_s - mt) * (r.chamber_c.unwrap() - mc)).sum();
        let sxx: f64 = rows.iter().map(|r| (r.t_s - mt).powi(2)).sum();
        sxy / sxx * 60.0
    };
    let up: Vec<&Row> =
        rows.iter().filter(|r| r.t_s < 9000.0 && r.chamber_c.unwrap() > 21.0 && r.chamber_c.unwrap() < 49.0).collect();
    let down: Vec<&Row> =
        rows.iter().filter(|r| r.t_s > 9000.0 && r.chamber_c.unwrap() > 21.0 && r.chamber_c.unwrap() < 49.0).collect();
    let (s_up, s_down) = (slope(&up), slope(&down));
    assert!((s_up - 0.25).abs() < 1e-4, "up at {s_up} °C/min");
    assert!((s_down + 1.0).abs() < 1e-4, "down at {s_down} °C/min");
    // 30 °C at 0.25 °C/min: the set point from 7200 s on; back at 1 °C/min: 1800 s later.
    let reached = |from: f64, c: f64| rows.iter().find(|r| r.t_s >= from && r.chamber_c == Some(c)).unwrap().t_s;
    let (t_up, t_down) = (reached(0.0, 50.0), reached(9000.0, 20.0));
    assert!((t_up - 7200.0).abs() <= 1.0, "{t_up}");
    assert!((t_down - 10_800.0).abs() <= 1.0, "{t_down}");
    println!(
        "soak rates: {s_up:.6} °C/min (asked 0.25), then {s_down:.6} (thermal 1); set points at {t_up} s and {t_down} s"
    );
}

fn load_err(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    std::fs::write(&p, text).unwrap();
    let e = scenario::load(&p).err().unwrap_or_else(|| panic!("accepted: {text}")).to_string();
    assert!(e.contains("bad.toml"), "{e}");
    e
}

#[test]
fn bad_power_and_rate_keys_name_the_step_and_the_key() {
    let head = "[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n";
    let hold = "[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 10.0\n";
    let e = load_err(&format!(
        "{head}{hold}[[step]]\nkind = \"soak\"\nchamber_C = 30.0\ndwell_s = 5.0\nrate_C_per_min = 0.0\n"
    ));
    assert!(e.contains("step[1].rate_C_per_min: must be > 0 (inf: jumps), got 0"), "{e}");
    let e = load_err(&format!("{head}{hold}[[step]]\nkind = \"power\"\noff_s = -1.0\n{hold}"));
    assert!(e.contains("step[1].off_s: must be > 0, got -1"), "{e}");
    let e = load_err(&format!("{head}{hold}[[step]]\nkind = \"power\"\noff_s = 1.0e9\n{hold}"));
    assert!(e.contains("step[1].off_s: must be within"), "{e}");
    let e = load_err(&format!("{head}{hold}[[step]]\nkind = \"power\"\noff_s = 60.0\n"));
    assert!(e.contains("step[1]: a power cycle must be followed by a step"), "{e}");
    let e = load_err(&format!("{head}[[step]]\nkind = \"power\"\noff_s = 60.0\non_s = 5.0\n{hold}"));
    assert!(e.contains("step[0]") && e.contains("unknown field `on_s`"), "{e}");
    let e = load_err(&format!("{head}[[step]]\nkind = \"power\"\n{hold}"));
    assert!(e.contains("step[0]") && e.contains("missing field `off_s`"), "{e}");
    let e = load_err(&format!("{head}[[step]]\nkind = \"power\"\noff_s = 60.0\nrate_C_per_min = 2.0\n{hold}"));
    assert!(e.contains("step[0].rate_C_per_min: only with chamber_C"), "{e}");
    let e = load_err(&format!("{head}[[step]]\nkind = \"power\"\noff_s = 60.0\nchamber_C = 900.0\n{hold}"));
    assert!(e.contains("step[0].chamber_C: must be a temperature"), "{e}");
}
