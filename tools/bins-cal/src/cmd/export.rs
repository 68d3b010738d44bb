//! `bins-cal export CAL.toml --px4 OUT.params --ardupilot OUT.parm`: the calibration's bias
//! against temperature as PX4's `TC_A*` and ArduPilot's `INS_TCAL*` parameters
//! ([`bins_cal::autopilot`], `docs/logs.md`), each checked against the calibration as its
//! firmware evaluates it; what the export loses (scale factors and cross-axis terms against
//! temperature, thermal dynamics) is printed, and with `--check` measured as the |g| error
//! T(13) of the exported model beside the full one in check dwells the calibration did not
//! use.

use anyhow::{anyhow, bail};
use bins_cal::autopilot::{self, ArduPilot, Px4, Raw};
use bins_cal::calfile::CalibrationFile;
use bins_cal::calib::segments::{self, Segment};
use bins_cal::fclog::G_M_S2;
use bins_cal::fsio;
use bins_comp::{Calibration, CalibrationParams, Method};
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal export`.
#[derive(clap::Args)]
pub struct Args {
    /// The calibration file (TOML).
    calib: PathBuf,
    /// Write PX4's TC_A* parameters (QGroundControl .params file).
    #[arg(long, value_name = "OUT.params", required_unless_present = "ardupilot")]
    px4: Option<PathBuf>,
    /// Write ArduPilot's INS_TCAL* parameters (.parm file, NAME,VALUE).
    #[arg(long, value_name = "OUT.parm")]
    ardupilot: Option<PathBuf>,
    /// The accelerometer instance: PX4 TC_A<N>, ArduPilot INS_TCAL<N+1> (the numbers of
    /// `bins-cal import`).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=2))]
    instance: u8,
    /// PX4's device_id of the sensor (TC_A<N>_ID; `bins-cal import` prints it). Without it
    /// 0, which PX4 matches with no sensor.
    #[arg(long, value_name = "ID", default_value_t = 0)]
    device_id: u32,
    /// What the autopilot's raw data are: the calibration's own acceleration at T0
    /// (calibrated), or the recording's signals at 1 V/g of a log from `bins-cal import`
    /// (logged).
    #[arg(long, value_enum, default_value_t = Raw::Calibrated)]
    raw: Raw,
    /// Recordings with check dwells the calibration did not use: the |g| error of the
    /// exported model beside the full one in each.
    #[arg(long, num_args = 1.., value_name = "REC.csv")]
    check: Vec<PathBuf>,
    /// Only dwells whose label starts with this.
    #[arg(long, default_value = "CP")]
    pos_prefix: String,
    #[command(flatten)]
    seg: segments::Options,
}

/// The largest |x| of a 3-vector.
fn max_abs(v: [f64; 3]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Runs `bins-cal export`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let outputs: Vec<&PathBuf> = [args.px4.as_ref(), args.ardupilot.as_ref()].into_iter().flatten().collect();
    fsio::refuse_overwriting_inputs(args.check.iter().chain([&args.calib]), outputs.iter())?;
    let (file, _) = CalibrationFile::read_checked(&args.calib)?;
    let (params, _) = file.to_params().map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let (lo, hi) = params.temp_range_c;
    let (cubic, fit_err_g) = autopilot::fit_cubic(&params, args.raw);
    let name = args.calib.display().to_string();
    let raw_text = match args.raw {
        Raw::Calibrated => "the calibration's acceleration at T0, K(T0)^-1 (U - U0(T0))",
        Raw::Logged => "the recording's signals at 1 V/g (a log from bins-cal import)",
    };
    println!(
        "{name}: bias b(T) = N (U0(T) - U0(T0)) over {lo} … {hi} °C, raw data: {raw_text}; cubic fit around {:.2} °C: largest error {:.4} µg",
        cubic.tref_c,
        fit_err_g * 1e6
    );
    let temps: Vec<f64> =
        (0..autopilot::FIT_POINTS).map(|k| lo + (hi - lo) * k as f64 / (autopilot::FIT_POINTS - 1) as f64).collect();
    let mut header = vec![
        format!("bins-cal export of {name} ({})", bins_cal::TOOL_VERSION),
        format!("accelerometer offset against temperature, {lo} ... {hi} degC; raw data: {raw_text}"),
        format!("cubic fit of the calibration's bias: largest error {:.4} ug over the range", fit_err_g * 1e6),
    ];
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    let px4 = args.px4.as_ref().map(|_| Px4::new(args.instance, args.device_id, &cubic, (lo, hi)));
    let ap = args.ardupilot.as_ref().map(|_| ArduPilot::new(args.instance + 1, &cubic, (lo, hi)));
    if let (Some(path), Some(p)) = (&args.px4, &px4) {
        let err = temps
            .iter()
            .map(|&t| {
                let o = p.offset_m_s2(t as f32);
                let b = autopilot::bias_g(&params, args.raw, t);
                max_abs([0, 1, 2].map(|i| o[i] as f64 / G_M_S2 - b[i]))
            })
            .fold(0.0, f64::max);
        if args.device_id == 0 {
            println!(
                "note: TC_A{}_ID = 0 matches no sensor: give --device-id (bins-cal import prints each instance's)",
                args.instance
            );
        }
        println!(
            "{}: PX4 TC_A{} as calc_thermal_offsets_3D evaluates it (f32) against the bias: largest difference {:.4} µg",
            path.display(),
            args.instance,
            err * 1e6
        );
        header.push(
            "PX4: src/modules/temperature_compensation/TemperatureCompensation.cpp, calc_thermal_offsets_3D".into(),
        );
        files.push((path.clone(), p.params_text(&header)));
        header.pop();
    }
    if let (Some(path), Some(p)) = (&args.ardupilot, &ap) {
        // Whatever the temperature of the autopilot's own calibration, the correction is the
        // change of the bias from it: checked at T0 and at the range's ends.
        let mut err: f64 = 0.0;
        for tc in [params.t0_c, lo, hi] {
            for &t in &temps {
                let c = p.correction_m_s2(t as f32, tc as f32);
                let (b, b0) = (autopilot::bias_g(&params, args.raw, t), autopilot::bias_g(&params, args.raw, tc));
                err = err.max(max_abs([0, 1, 2].map(|i| c[i] as f64 / G_M_S2 - (b[i] - b0[i]))));
            }
        }
        println!(
            "{}: ArduPilot INS_TCAL{} as correct_sensor evaluates it (f32) against the bias change from the accelerometer calibration's temperature: largest difference {:.4} µg",
            path.display(),
            args.instance + 1,
            err * 1e6
        );
        header.push("ArduPilot: libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp, correct_sensor".into());
        files.push((path.clone(), p.params_text(&header)));
        header.pop();
    }
    print_losses(&params, &file, args.raw)?;
    if !args.check.is_empty() {
        check(&args, &params, px4.as_ref(), ap.as_ref())?;
    }
    let outputs: Vec<(&Path, &[u8])> = files.iter().map(|(p, t)| (p.as_path(), t.as_bytes())).collect();
    fsio::write_all_or_nothing(&outputs)?;
    for (p, _) in &files {
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// What neither autopilot can hold: the scale-factor and cross-axis changes with
/// temperature (the error they leave at 1 g along each axis), the thermal dynamics.
fn print_losses(p: &CalibrationParams, file: &CalibrationFile, raw: Raw) -> anyhow::Result<()> {
    let (lo, hi) = p.temp_range_c;
    let k0 = nalgebra::Matrix3::from_fn(|i, j| p.constants.k_v_per_g[i][j]);
    let n0 = k0.try_inverse().ok_or_else(|| anyhow!("K at T0 is singular"))?;
    let (mut worst, mut at) = (0.0_f64, lo);
    for k in 0..autopilot::FIT_POINTS {
        let t = lo + (hi - lo) * k as f64 / (autopilot::FIT_POINTS - 1) as f64;
        let kt = p.constants_at(t).k_v_per_g;
        let e = n0 * nalgebra::Matrix3::from_fn(|i, j| kt[i][j]) - nalgebra::Matrix3::identity();
        let m = e.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        if m > worst {
            (worst, at) = (m, t);
        }
    }
    println!(
        "not exported: scale factors and cross-axis terms against temperature, up to {:.4} mg per g of input (at {at:.1} °C)",
        worst * 1e3
    );
    if file.thermal_dynamics.is_some() {
        println!(
            "not exported: the thermal dynamics ([thermal_dynamics]): both autopilots evaluate at the temperature read"
        );
    }
    if raw == Raw::Logged {
        let d = (k0 - nalgebra::Matrix3::identity()).iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        println!(
            "raw data logged: K(T0) differs from 1 V/g by up to {:.4} % (the autopilot's own scale calibration, applied after the offsets)",
            d * 100.0
        );
    }
    Ok(())
}

/// A model's acceleration \[g\] from the signals \[V\] and the temperature [°C].
type Model<'a> = Box<dyn Fn([f64; 3], f64) -> [f64; 3] + 'a>;

/// The |g| error T(13) \[mg\] of the full model, the T0 constants and each export in the
/// check dwells of `args.check`, max |Δg| per check temperature.
fn check(args: &Args, p: &CalibrationParams, px4: Option<&Px4>, ap: Option<&ArduPilot>) -> anyhow::Result<()> {
    let full = Calibration::new(p).map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let t0 = Calibration::new(&p.with_method(Method::Uncorrected)).map_err(|e| anyhow!("{e}"))?;
    let k0 = nalgebra::Matrix3::from_fn(|i, j| p.constants.k_v_per_g[i][j]);
    let n0 = k0.try_inverse().ok_or_else(|| anyhow!("K at T0 is singular"))?;
    let u00 = nalgebra::Vector3::from(p.constants.u0_v);
    // The exported chain in the calibration's terms: a = K0⁻¹ (U − U0(T0) − N⁻¹ b_exp(T)).
    let exported = |u: [f64; 3], b_g: [f64; 3]| -> [f64; 3] {
        let b = nalgebra::Vector3::from(b_g);
        let v = nalgebra::Vector3::from(u) - u00;
        let a = match args.raw {
            Raw::Calibrated => n0 * v - b,
            Raw::Logged => n0 * (v - b),
        };
        [a[0], a[1], a[2]]
    };
    let (all, files) = segments::find_all(&args.check, &args.seg)?;
    let holds: Vec<Segment> = all
        .into_iter()
        .filter(|s| s.pos.starts_with(&args.pos_prefix) && s.rate_c_per_min.abs() <= args.seg.max_rate_c_per_min)
        .collect();
    let groups = segments::by_temperature(&holds, args.seg.temp_tol_c);
    if groups.is_empty() {
        bail!("{files}: no stationary check dwell (label {}…) with a settled temperature", args.pos_prefix);
    }
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let dg = |s: &Segment, f: &dyn Fn([f64; 3], f64) -> [f64; 3]| {
        let mut sum = [0.0; 3];
        for (u, t) in &s.rows {
            let a = f(*u, *t);
            for i in 0..3 {
                sum[i] += a[i];
            }
        }
        (norm(sum.map(|x| x / s.rows.len() as f64)) - norm(s.f_g)) * 1e3
    };
    let mut cols: Vec<(&str, Model)> = vec![
        ("T0 constants", Box::new(|u, t| t0.compensate(u, t).accel_g)),
        ("full model", Box::new(|u, t| full.compensate(u, t).accel_g)),
    ];
    if let Some(x) = px4 {
        cols.push((
            "PX4 export",
            Box::new(move |u, t| exported(u, x.offset_m_s2(t as f32).map(|o| o as f64 / G_M_S2))),
        ));
    }
    if let Some(x) = ap {
        let tc = p.t0_c as f32;
        cols.push((
            "ArduPilot export",
            Box::new(move |u, t| exported(u, x.correction_m_s2(t as f32, tc).map(|o| o as f64 / G_M_S2))),
        ));
    }
    println!(
        "held-out check: max |Δg| T(13) [mg] in the {} dwells of {files} (not used by the calibration; ArduPilot with its accelerometer calibrated at T0 = {} °C)",
        args.pos_prefix, p.t0_c
    );
    print!("{:>10}", "temp °C");
    for (n, _) in &cols {
        print!(" {n:>17}");
    }
    println!();
    for (t, segs) in &groups {
        print!("{t:>+10.1}");
        for (_, f) in &cols {
            let m = segs.iter().map(|s| dg(s, f.as_ref()).abs()).fold(0.0, f64::max);
            print!(" {m:>17.4}");
        }
        println!();
    }
    Ok(())
}
