//! `bins-cal calibrate --shaker`: prints the shake-table holds and the VE fits of
//! [`bins_cal::calib::shaker`] (physics §8) and returns the VE model.

use bins_cal::calib::segments::Options;
use bins_cal::calib::shaker::{
    CF_NAMES, Hold, ShakerResult, axis_name, cf_values, find_holds, identify, kind_of, pairs,
};
use bins_comp::{Constants, Variant};
use std::path::PathBuf;

/// Prints the holds of the shake-table recordings.
fn print_holds(holds: &[Hold]) {
    println!("\nshake-table holds (ΔU = shaking hold − quiet hold at the same position; std about the fitted sine):");
    println!(
        "  {:<24} {:<5} {:<6} {:>7} {:>8} {:>8} {:>5} {:>8} {:>10} {:>10} {:>10} {:>10}  status",
        "file", "pos", "vib", "level_g", "from_s", "to_s", "rows", "temp_C", "std_mV", "dUx_uV", "dUy_uV", "dUz_uV"
    );
    for h in holds {
        let name = h.file.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        let du = match h.du_v {
            Some(d) => d.map(|x| format!("{:>10.3}", x * 1e6)).join(" "),
            None => format!("{:>10} {:>10} {:>10}", "-", "-", "-"),
        };
        println!(
            "  {:<24} {:<5} {:<6} {:>7.3} {:>8.1} {:>8.1} {:>5} {:>8.2} {:>10.4} {}  {}",
            name,
            h.pos,
            kind_of(&h.vib),
            h.vib.level_g(),
            h.t_s.0,
            h.t_s.1,
            h.n,
            h.temp_c,
            h.std_u_v.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3,
            du,
            h.rejected.as_deref().unwrap_or("used")
        );
    }
}

/// Finds the holds of the shake-table recordings, identifies the VE of every accelerometer
/// shaken along its input axis on a plan, prints every hold and fit, and returns the VE model.
/// `constants_at(T)` gives the unit's constants (for `K_ii`) at temperature `T`.
pub fn calibrate(
    paths: &[PathBuf],
    opt: &Options,
    variant: Variant,
    constants_at: impl Fn(f64) -> Constants<f64>,
) -> anyhow::Result<ShakerResult> {
    let files = paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    let (holds, pairs_idx) = find_holds(paths, opt)?;
    print_holds(&holds);
    let pairs = pairs(&holds, &pairs_idx);
    let id = identify(&pairs, &files, constants_at)?;
    for a in &id.axes {
        let i = a.axis;
        println!(
            "\n{} accelerometer (IA = {}): {} sine position(s) at {} level(s), {} random; K_ii = {:.6} V/g",
            axis_name(i),
            axis_name(i),
            a.n_sine,
            a.levels_g.len(),
            a.n_random,
            a.k1_v_per_g
        );
        println!("  V(22) per level (least squares over its positions; residual = measured − fitted ΔU/K1):");
        println!(
            "  {:>7} {:>3} {:>11} {:>11} {:>11} {:>12} {:>12} {:>12} {:>9}  positions",
            "level_g", "n", "D0_1_ug", "D0_2_ug", "D0_3_ug", "d1_ug_per_g", "d2_ug_per_g2", "d3_ug_per_g3", "resid_ug"
        );
        for lf in &a.level_fits {
            let l = lf.level_g;
            match &lf.fit {
                Ok((f, resid)) => {
                    let t = f.terms;
                    let cross = |d: bool, v: f64| if d { format!("{:>11.4}", v * 1e6) } else { format!("{:>11}", "-") };
                    println!(
                        "  {:>7.3} {:>3} {:>11.4} {} {} {:>12.4} {:>12.4} {:>12.4} {:>9.4}  {}",
                        l,
                        lf.n,
                        t.d0_1_g * 1e6,
                        cross(f.cross_determined[0], t.d0_2_g),
                        cross(f.cross_determined[1], t.d0_3_g),
                        t.delta1_g_per_g * 1e6,
                        t.delta2_g_per_g2 * 1e6,
                        t.delta3_g_per_g3 * 1e6,
                        resid * 1e6,
                        lf.names.join(" ")
                    );
                }
                Err(e) => println!("  {:>7.3} {:>3} not fitted: {e}  {}", l, lf.n, lf.names.join(" ")),
            }
        }
        let c = match &a.conversion {
            Ok(c) => c,
            Err(e) => return Err(anyhow::anyhow!("{e:#}")),
        };
        println!(
            "  conversion function over {} sine positions at {} levels (exact variant; residual σ {:.4} µg, ΔU noise {:.4} µg):",
            c.n_positions,
            a.levels_g.len(),
            c.fit.residual_sigma_g * 1e6,
            c.noise_g * 1e6
        );
        println!("  {:<14} {:>14} {:>12} {:>8}", "coefficient", "value", "std_error", "rel_%");
        let vals = cf_values(&c.fit.cf);
        let se = c.se;
        for k in 0..7 {
            if c.fit.determined[k] {
                let rel = if vals[k] != 0.0 { (se[k] / vals[k]).abs() * 100.0 } else { f64::INFINITY };
                println!("  {:<14} {:>14.6e} {:>12.3e} {:>8.2}", CF_NAMES[k], vals[k], se[k], rel);
            } else {
                println!(
                    "  {:<14} {:>14} {:>12} {:>8}  not determined (no vibration on that axis): 0",
                    CF_NAMES[k], 0, "-", "-"
                );
            }
        }
        if !c.random.is_empty() {
            println!("  random holds (not fitted): measured ΔU/K1 vs the identified function's VE (exact variant):");
            println!(
                "  {:<5} {:>7} {:>8} {:>12} {:>12} {:>12}",
                "pos", "sigma_g", "a_p3_g", "meas_ug", "pred_ug", "se_ug"
            );
            for r in &c.random {
                println!(
                    "  {:<5} {:>7.3} {:>8.4} {:>12.3} {:>12.3} {:>12.3}",
                    r.pos,
                    r.sigma_g,
                    r.a_p3_g,
                    r.meas_g * 1e6,
                    r.pred_g * 1e6,
                    r.se_g * 1e6
                );
            }
        }
    }
    for s in &id.skipped {
        println!("  not identified: {s}: not a plan (needs sine at 4 or more distinct static accelerations)");
    }
    id.into_result(&files, variant)
}
