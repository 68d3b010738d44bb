//! The coefficient files of `vibration --cf` and `tempco --constants` are held to the
//! firmware's physical limits (`bins_comp::blob::limits`, `coefficient_limit`): an absurd
//! constant is refused in one line naming the file, the line and the column, before any table
//! is printed (a k2 of 1e300 µg/g² used to print a 300-digit table); the papers' own tables
//! pass.

#[allow(dead_code)]
mod common;

use common::csv_text::Csv;
use common::{err, ok, repo};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_conversion_coefficient_beyond_the_firmwares_limit_is_refused_naming_its_column() {
    let d = tempfile::tempdir().unwrap();
    let env = repo("data/vibration-env-paper.toml");
    let good = repo("data/al15-coefficients.csv");
    ok(&["vibration", "--cf", s(&good), "--env", s(&env)]);
    // Each column in its unit, just beyond its limit (and 1e300 for k2).
    let cases = [
        ("a0_mg", "1001"),
        ("delta_1A_ppm", "-100001"),
        ("k2_ug_per_g2", "1e300"),
        ("k3_ug_per_g3", "1001"),
        ("k4_ug_per_g4", "101"),
        ("k5_ug_per_g5", "10.1"),
        ("m1_mg_per_g", "501"),
        ("m2_mg_per_g", "-501"),
        ("m31_ug_per_g2", "10001"),
        ("m32_ug_per_g2", "-10001"),
    ];
    for (col, value) in cases {
        let mut cf = Csv::read(&good);
        let c = cf.col(col);
        cf.rows[0][c] = value.into();
        let path = d.path().join(format!("{col}.csv"));
        cf.write(&path);
        let e = err(&["vibration", "--cf", s(&path), "--env", s(&env)]);
        assert!(e.contains(&format!("`{col}`")) && e.contains(&format!("`{value}`")), "{e}");
        assert!(e.contains(&format!("{col}.csv:")), "{e}");
        assert!(e.len() < 400, "{e}");
    }
}

#[test]
fn constants_beyond_the_firmwares_limits_are_refused_naming_their_column() {
    let d = tempfile::tempdir().unwrap();
    let good = repo("data/paper-constants.csv");
    ok(&["tempco", "--constants", s(&good)]);
    // A scale factor of 2000 V/g, a cross-axis term as large as the axis, an offset of 500 V.
    for (col, value) in [("Kyy", "2000"), ("Kzx", "-0.5"), ("U0x", "500")] {
        let mut t = Csv::read(&good);
        let c = t.col(col);
        t.rows[2][c] = value.into();
        let path = d.path().join(format!("{col}.csv"));
        t.write(&path);
        let e = err(&["tempco", "--constants", s(&path)]);
        assert!(e.contains(&format!("column `{col}`")), "{e}");
    }
}
