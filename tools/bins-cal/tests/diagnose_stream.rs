//! The diagnosis reads its two recordings in lockstep, row by row, without holding either
//! ([`bins_cal::diagnose::prepare_files`]): what it builds must be what the in-memory path
//! builds from the whole files ([`bins_cal::diagnose::prep::prepare`] on `read_all`), on a
//! generated pair with vibration, on the real sweep in `data/real/`, and on pairs whose rows
//! change kind part-way (vibration cells first empty, rows without a reference, `power_s`
//! missing on some rows); and a bad pair is refused with the same one-line error.

use bins_cal::diagnose::{cases, prep, prepare_files};
use bins_cal::recording::{Row, VibKind, read_all};
use std::path::{Path, PathBuf};

#[allow(dead_code)] // the helpers other test files use
mod common;
use common::write_recording as write;

/// The in-memory path on the same files.
fn whole(sim: &Path, real: &Path) -> Result<prep::Prepared, String> {
    let (_, s) = read_all(sim).map_err(|e| e.to_string())?;
    let (_, r) = read_all(real).map_err(|e| e.to_string())?;
    prep::prepare(&s, &r, sim, real).map_err(|e| e.0)
}

/// Both paths give the same result, every field to the last bit (`{:?}` of an `f64` is its
/// shortest round-trip form), or the same error.
fn same_both_ways(sim: &Path, real: &Path) -> Result<prep::Prepared, String> {
    let streamed = prepare_files(sim, real, false).map_err(|e| e.0);
    let held = whole(sim, real);
    assert_eq!(format!("{streamed:?}"), format!("{held:?}"));
    streamed
}

fn pair(dir: &Path, sim: &[Row], real: &[Row]) -> (PathBuf, PathBuf) {
    let (sp, rp) = (dir.join("sim.csv"), dir.join("real.csv"));
    write(&sp, sim);
    write(&rp, real);
    (sp, rp)
}

#[test]
fn lockstep_reading_builds_what_the_whole_files_build() {
    let dir = tempfile::tempdir().unwrap();
    // A suite case with vibration.
    let mut case = cases::suite().into_iter().find(|c| c.name == "k2_vibration_only").unwrap();
    case.plan.rows = 6_000;
    let (s, r) = cases::generate(&case);
    let (sp, rp) = pair(dir.path(), &s, &r);
    let p = same_both_ways(&sp, &rp).expect("prepared");
    assert!(p.vib_names.len() > 1, "{:?}", p.vib_names);
    assert_eq!(p.n_total, 6_000);

    // The real sweep (cells left out at the ends of lines).
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/real");
    let p = same_both_ways(&data.join("tofupilot-sweep-sim.csv"), &data.join("tofupilot-sweep-real.csv"))
        .expect("prepared");
    assert!(p.t.len() > 1000, "{} rows", p.t.len());

    // Vibration cells empty on the first rows, then known: the first rows are not usable (their
    // vibration is not known) once any row has one; some rows without a reference; power_s on
    // some rows only.
    let (mut s2, mut r2) = (s.clone(), r.clone());
    for k in 0..400 {
        for rows in [&mut s2, &mut r2] {
            rows[k].vib_kind = None;
            rows[k].vib_g = [None; 3];
            rows[k].vib_hz = None;
            rows[k].vib_bw_hz = None;
        }
    }
    for k in (1000..1500).step_by(7) {
        s2[k].clear_reference();
        r2[k].clear_reference();
    }
    for k in 0..s2.len() {
        let power = (!(2000..2100).contains(&k)).then_some(k as f64);
        s2[k].power_s = power;
        r2[k].power_s = power;
    }
    let (sp, rp) = pair(dir.path(), &s2, &r2);
    let p = same_both_ways(&sp, &rp).expect("prepared");
    assert!(p.skipped > 400, "{}", p.skipped);
    assert!(p.power.is_none() && p.notes.iter().any(|n| n.contains("power_s")), "{:?}", p.notes);
    // Data row k is on line k + 3 (a comment line and the header before it).
    assert_eq!(p.line[0], 403, "first usable row: the first with its vibration known");

    // Only the first rows have no vib_kind, the rest `none`: all vibration-free.
    let (mut s3, mut r3) = (s2[..600].to_vec(), r2[..600].to_vec());
    for rows in [&mut s3, &mut r3] {
        for row in rows[400..].iter_mut() {
            row.set_vibration(&bins_comp::vibration::Vibration::None);
        }
    }
    assert_eq!(r3[500].vib_kind, Some(VibKind::None));
    let (sp, rp) = pair(dir.path(), &s3, &r3);
    let p = same_both_ways(&sp, &rp).expect("prepared");
    assert_eq!(p.vib_names, ["none"]);
}

#[test]
fn a_bad_pair_is_refused_with_the_same_error_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let mut case = cases::suite().into_iter().find(|c| c.name == "thermal_lag").unwrap();
    case.plan.rows = 500;
    let (s, r) = cases::generate(&case);
    // Row counts differ: both counted.
    let (sp, rp) = pair(dir.path(), &s, &r[..450]);
    let e = same_both_ways(&sp, &rp).unwrap_err();
    assert!(e.contains("450 data rows") && e.contains("has 500"), "{e}");
    let (sp, rp) = pair(dir.path(), &s[..300], &r);
    let e = same_both_ways(&sp, &rp).unwrap_err();
    assert!(e.contains("500 data rows") && e.contains("has 300"), "{e}");
    // An empty file.
    let (sp, rp) = pair(dir.path(), &s, &[]);
    let e = same_both_ways(&sp, &rp).unwrap_err();
    assert!(e.ends_with("no data rows"), "{e}");
    // A row that does not match: REAL's file and line, SIM's line.
    let mut r2 = r.clone();
    r2[321].f_g[1] = Some(0.5);
    let (sp, rp) = pair(dir.path(), &s, &r2);
    let e = same_both_ways(&sp, &rp).unwrap_err();
    assert!(e.contains("real.csv:324: column `fy_g`") && e.contains("line 324 of"), "{e}");
    // A dead REAL channel.
    let mut r3 = r.clone();
    r3.iter_mut().for_each(|row| row.u_v[2] = 1.25);
    let (sp, rp) = pair(dir.path(), &s, &r3);
    let e = same_both_ways(&sp, &rp).unwrap_err();
    assert!(e.contains("column `uz_V` is constant (1.25 V)"), "{e}");
}
