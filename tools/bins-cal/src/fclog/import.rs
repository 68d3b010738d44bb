//! A flight-controller log into recordings (format v1), one per accelerometer instance, in
//! one streaming pass with a progress bar (`bins-cal import`, `docs/logs.md`).
//!
//! Each sample becomes a row: `t_s` the log's clock \[s since the autopilot's boot\] (the same
//! clock for every instance, so the files line up row for row where the log samples the
//! instances together); `ux_V`, `uy_V`, `uz_V` the logged acceleration divided by
//! [`G_M_S2`], in g at a nominal 1 V/g, in the log's own axes and signs;
//! `temp_C` the temperature logged with it. The header's comments say the source, the
//! message, the fields and the frame. What a log cannot say — the rig's reference, the
//! position label — is left out, as the format allows. The files are written to temporary
//! files and put in place together at the end, or not at all (`fsio::commit_all`).

use super::{G_M_S2, Instance, LogError, Sample, Summary};
use crate::fsio::{self, AtomicFile};
use crate::recording::{Columns, Row, Writer};
use std::path::{Path, PathBuf};

/// What to import.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// Only this instance (the log's own number), into the output itself; `None`: every
    /// instance, each into its own file ([`output_for`]).
    pub instance: Option<u8>,
    /// The acceleration of this instance (its latest sample, in g) as the reference
    /// `fx_g`, `fy_g`, `fz_g` of every other instance's rows: a co-located accelerometer of
    /// the same log as the "rig", so that `calibrate` and `diagnose` can compare one with
    /// another. Meaningful where the log's instances share their axes (ArduPilot's IMU
    /// messages are all in the body frame; PX4's sensor_accel each in its own sensor frame).
    pub reference: Option<u8>,
    /// Only the samples of this span of the log's clock \[s\] (`None`: from the start, to the
    /// end): a static period on the ground, say, rather than the flight.
    pub span_s: (Option<f64>, Option<f64>),
    /// Show a progress bar on standard error (indicatif draws nothing when it is not a
    /// terminal).
    pub progress: bool,
}

/// One recording written.
#[derive(Clone, Debug, PartialEq)]
pub struct Imported {
    /// The file.
    pub path: PathBuf,
    /// The instance it holds.
    pub instance: Instance,
    /// Rows written.
    pub rows: u64,
    /// First and last `t_s` \[s\].
    pub t_s: (f64, f64),
    /// Lowest and highest `temp_C` [°C].
    pub temp_c: (f64, f64),
}

/// The file of instance `index` when every instance is imported: `REC.csv` → `REC-index.csv`.
pub fn output_for(out: &Path, index: u8) -> PathBuf {
    let stem = out.file_stem().map_or_else(|| "rec".into(), |s| s.to_string_lossy().into_owned());
    let name = match out.extension() {
        Some(e) => format!("{stem}-{index}.{}", e.to_string_lossy()),
        None => format!("{stem}-{index}"),
    };
    out.with_file_name(name)
}

/// The comment lines of an instance's recording.
fn comments(log: &Path, format: super::Format, inst: &Instance) -> Vec<String> {
    let name = log.file_name().map_or_else(|| log.display().to_string(), |n| n.to_string_lossy().into_owned());
    let mut c = vec![
        format!("recording format v1 -- imported by {} from {name} ({})", crate::TOOL_VERSION, format.name()),
        format!(
            "source: message {}, instance {}{}; time {}, acceleration {}, temperature {}",
            inst.message,
            inst.index,
            inst.device_id.map_or(String::new(), |d| format!(", device_id {d}")),
            inst.time_field,
            match format {
                super::Format::ULog => "x y z",
                super::Format::DataFlash => "AccX AccY AccZ",
            },
            inst.temp_field
        ),
        format!(
            "ux_V, uy_V, uz_V: the logged acceleration [m/s^2] / {G_M_S2}, i.e. g at a nominal 1 V/g, in the log's own axes and signs"
        ),
    ];
    c.push(match format {
        super::Format::ULog => "frame: PX4 sensor_accel, the sensor's frame before the calibration (CAL_ACC*) and the thermal offsets (TC_A*)".into(),
        super::Format::DataFlash => "frame: ArduPilot IMU, the body frame after the autopilot's temperature calibration (INS_TCAL*), offsets and scale factors (INS_ACC*) and board orientation, low-pass filtered".into(),
    });
    c.push(
        "t_s: the log's clock, s since the autopilot's boot; no rig reference (fx_g..fz_g, pos): the log cannot say"
            .into(),
    );
    c
}

/// An instance's writer and its running figures.
struct Out {
    index: u8,
    instance: Instance,
    path: PathBuf,
    writer: Writer<AtomicFile>,
    t_s: (f64, f64),
    temp_c: (f64, f64),
}

/// Imports `log` into `out` (one instance, [`Options::instance`]) or into `REC-N.csv` beside
/// it for every instance N. Nothing is written unless the whole log was read without an
/// error; then every file is put in place together.
pub fn import(log: &Path, out: &Path, opt: &Options) -> anyhow::Result<(Summary, Vec<Imported>)> {
    let size = std::fs::metadata(log).map(|m| m.len()).unwrap_or(0);
    let bar = if opt.progress { indicatif::ProgressBar::new(size) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template("import {bar:30} {bytes}/{total_bytes}, {elapsed}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut outs: Vec<Out> = Vec::new();
    let format = super::format_of(log);
    let mut row = Row::default();
    // The reference instance's latest sample [g].
    let mut reference: Option<[f64; 3]> = None;
    let result = super::read(log, &mut |b| bar.set_position(b), &mut |inst: &Instance, s: &Sample| {
        let is_reference = opt.reference == Some(s.instance);
        if is_reference {
            reference = Some(s.accel_m_s2.map(|a| a / G_M_S2));
        }
        let t_s = s.time_us as f64 / 1e6;
        if opt.instance.is_some_and(|k| k != s.instance)
            || opt.span_s.0.is_some_and(|a| t_s < a)
            || opt.span_s.1.is_some_and(|b| t_s > b)
        {
            return Ok(());
        }
        // Rows before the reference's first sample have no reference: left out.
        if opt.reference.is_some() && !is_reference && reference.is_none() {
            return Ok(());
        }
        let k = match outs.iter().position(|o| o.index == s.instance) {
            Some(k) => k,
            None => {
                let path = if opt.instance.is_some() { out.to_path_buf() } else { output_for(out, s.instance) };
                let fail = |e: &dyn std::fmt::Display| LogError {
                    file: path.clone(),
                    offset: None,
                    message: None,
                    what: e.to_string(),
                };
                let file = AtomicFile::create(&path).map_err(|e| fail(&format!("{e:#}")))?;
                let mut lines = comments(log, format.unwrap_or(super::Format::DataFlash), inst);
                let with_reference = opt.reference.is_some() && !is_reference;
                if let (true, Some(r)) = (with_reference, opt.reference) {
                    lines.push(format!(
                        "fx_g, fy_g, fz_g: instance {r}'s acceleration / {G_M_S2} at its latest sample (bins-cal import --reference {r}), not a rig's"
                    ));
                }
                let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
                let columns = Columns { reference: with_reference, ..Columns::default() };
                let writer = Writer::new(file, &path, columns, &refs).map_err(|e| fail(&e))?;
                outs.push(Out {
                    index: s.instance,
                    instance: inst.clone(),
                    path,
                    writer,
                    t_s: (f64::INFINITY, f64::NEG_INFINITY),
                    temp_c: (f64::INFINITY, f64::NEG_INFINITY),
                });
                outs.len() - 1
            }
        };
        let o = &mut outs[k];
        row.t_s = t_s;
        row.u_v = s.accel_m_s2.map(|a| a / G_M_S2);
        row.temp_c = s.temp_c;
        row.f_g = match reference {
            Some(f) if !is_reference => f.map(Some),
            _ => [None; 3],
        };
        o.writer.write_row(&row).map_err(|e| LogError {
            file: log.to_path_buf(),
            offset: Some(s.offset),
            message: Some(inst.message.clone()),
            what: format!("not written: {e}"),
        })?;
        o.t_s = (o.t_s.0.min(row.t_s), o.t_s.1.max(row.t_s));
        o.temp_c = (o.temp_c.0.min(s.temp_c), o.temp_c.1.max(s.temp_c));
        Ok(())
    });
    bar.finish_and_clear();
    let summary = result?;
    for (what, k) in [("", opt.instance), (" for --reference", opt.reference)] {
        if let Some(k) = k
            && summary.position(k).is_none()
        {
            let have: Vec<String> = summary.instances.iter().map(|i| format!("{} ({})", i.index, i.message)).collect();
            anyhow::bail!("{}: no accelerometer instance {k}{what}; the log has {}", log.display(), have.join(", "));
        }
    }
    if outs.is_empty() {
        anyhow::bail!(
            "{}: no accelerometer sample in {} … {} s of the log's clock",
            log.display(),
            opt.span_s.0.map_or("the start".into(), |a| a.to_string()),
            opt.span_s.1.map_or("the end".into(), |b| b.to_string())
        );
    }
    let mut files = Vec::with_capacity(outs.len());
    let mut imported = Vec::with_capacity(outs.len());
    for o in outs {
        let rows = o.writer.rows();
        files.push(o.writer.finish()?);
        imported.push(Imported { path: o.path, instance: o.instance, rows, t_s: o.t_s, temp_c: o.temp_c });
    }
    fsio::commit_all(files)?;
    Ok((summary, imported))
}
