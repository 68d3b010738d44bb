//! Flight-controller logs (`docs/logs.md`): PX4 ULog ([`ulog`]) and ArduPilot DataFlash
//! ([`dataflash`]) read in one stream for their accelerometers and the temperature each logs
//! beside them, and written as recordings, format v1 ([`import`]).
//!
//! Owns what the two readers share: the format told by the file's first bytes ([`Format`]),
//! one accelerometer instance of a log ([`Instance`]) and one of its samples ([`Sample`]), the
//! check every sample passes ([`check_sample`]), and the errors, which name the file, the byte
//! offset of the message and the message ([`LogError`]). The readers hold one message at a
//! time: memory is bounded by the largest message (64 KiB in a ULog, 255 bytes in a
//! DataFlash log) and the message definitions, never by the file.

pub mod dataflash;
pub mod import;
pub mod ulog;

use crate::recording::{SIGNAL_LIMIT, TEMP_LIMIT};
use std::fmt;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// Standard gravity \[m/s² per g\]: the value PX4 (`CONSTANTS_ONE_G`) and ArduPilot
/// (`GRAVITY_MSS`) use, and the one the import divides the logged acceleration by.
pub const G_M_S2: f64 = 9.80665;

/// The largest acceleration a sample may hold \[m/s²\]: the recording format's signal range
/// (±100 V) at the import's nominal 1 V/g. The accelerometers of flight controllers saturate
/// at 16–32 g; a larger value is a corrupted message, not a reading.
pub const MAX_ACCEL_M_S2: f64 = SIGNAL_LIMIT.max * G_M_S2;

/// The kind of a log, told by its first bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// PX4 ULog: the file starts with `ULog` 0x01 0x12 0x35.
    ULog,
    /// ArduPilot DataFlash (`.bin`): the file starts with a message header 0xA3 0x95.
    DataFlash,
}

impl Format {
    /// The format of a file starting with `head` (its first bytes, at least 7 where the file
    /// has them), or `None`.
    pub fn detect(head: &[u8]) -> Option<Format> {
        if head.starts_with(ulog::MAGIC) {
            Some(Format::ULog)
        } else if head.starts_with(&dataflash::HEADER) {
            Some(Format::DataFlash)
        } else {
            None
        }
    }

    /// Its name, for messages and headers.
    pub fn name(self) -> &'static str {
        match self {
            Format::ULog => "PX4 ULog",
            Format::DataFlash => "ArduPilot DataFlash",
        }
    }
}

/// One accelerometer of a log, as the log names it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Instance {
    /// The log's own instance number: ULog `multi_id` of `sensor_accel`; DataFlash field `I`
    /// of `IMU` (new style), or 0, 1, 2 for `IMU`, `IMU2`, `IMU3` (old style).
    pub index: u8,
    /// The message it comes in (`sensor_accel`, `IMU`, `IMU2`, `IMU3`).
    pub message: String,
    /// The field its time is read from (`timestamp_sample`, `timestamp`, `TimeUS`, `TimeMS`).
    pub time_field: String,
    /// The field its temperature is read from (`temperature`, `T`, `Temp`).
    pub temp_field: String,
    /// PX4's `device_id` (the key of `TC_A*_ID` and `CAL_ACC*_ID`), where the log has one.
    pub device_id: Option<u32>,
}

/// One sample of an accelerometer instance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// The instance ([`Instance::index`]).
    pub instance: u8,
    /// The log's time of the sample \[µs\] (since the autopilot's boot).
    pub time_us: u64,
    /// The logged acceleration x, y, z \[m/s²\], in the log's own axes and signs.
    pub accel_m_s2: [f64; 3],
    /// The logged temperature [°C].
    pub temp_c: f64,
    /// Byte offset of the message in the file.
    pub offset: u64,
}

/// What a reader found in a log, besides the samples it handed out.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// The log's format.
    pub format: Format,
    /// Every accelerometer instance, in the order of its first sample.
    pub instances: Vec<Instance>,
    /// Samples per instance, in the order of `instances`.
    pub samples: Vec<u64>,
    /// Messages in the file (of every kind).
    pub messages: u64,
    /// The file's length \[B\].
    pub bytes: u64,
}

impl Summary {
    /// The position of instance `index` in [`instances`](Self::instances).
    pub fn position(&self, index: u8) -> Option<usize> {
        self.instances.iter().position(|i| i.index == index)
    }
}

/// A log that cannot be imported: the file, the byte offset and name of the message where
/// that was found (when it is tied to one), and why.
#[derive(Clone, Debug, PartialEq)]
pub struct LogError {
    /// The log.
    pub file: PathBuf,
    /// Byte offset of the message in the file.
    pub offset: Option<u64>,
    /// The message (`IMU2`, `sensor_accel`, `FMT`, …).
    pub message: Option<String>,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(o) = self.offset {
            write!(f, ": byte {o}")?;
        }
        if let Some(m) = &self.message {
            write!(f, ": {m}")?;
        }
        write!(f, ": {}", self.what)
    }
}

impl std::error::Error for LogError {}

/// A byte stream with its offset, read message by message; its offset is what the progress
/// bar shows.
pub(crate) struct Src<R> {
    r: R,
    /// Bytes consumed.
    pub(crate) offset: u64,
    file: PathBuf,
}

impl<R: Read> Src<R> {
    pub(crate) fn new(r: R, file: &Path) -> Self {
        Src { r, offset: 0, file: file.to_path_buf() }
    }

    /// Fills `buf` as far as the file goes; returns how many bytes it got (fewer only at the
    /// end of the file).
    pub(crate) fn fill(&mut self, buf: &mut [u8]) -> Result<usize, LogError> {
        let mut n = 0;
        while n < buf.len() {
            match self.r.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.error(Some(self.offset + n as u64), None, e.to_string())),
            }
        }
        self.offset += n as u64;
        Ok(n)
    }

    /// An error of this file.
    pub(crate) fn error(&self, offset: Option<u64>, message: Option<&str>, what: impl Into<String>) -> LogError {
        LogError { file: self.file.clone(), offset, message: message.map(str::to_string), what: what.into() }
    }
}

/// The check every sample passes before it is handed out: finite, the acceleration within
/// ±[`MAX_ACCEL_M_S2`], the temperature within the recording format's range. The error names
/// the field and the value.
pub fn check_sample(
    accel_m_s2: &[f64; 3],
    accel_fields: [&str; 3],
    temp_c: f64,
    temp_field: &str,
) -> Result<(), String> {
    for (a, name) in accel_m_s2.iter().zip(accel_fields) {
        if !a.is_finite() {
            return Err(format!("{name} = {a} is not a finite number"));
        }
        if a.abs() > MAX_ACCEL_M_S2 {
            return Err(format!(
                "{name} = {a} m/s² is beyond ±{MAX_ACCEL_M_S2} m/s² (±{} g): not an accelerometer reading",
                SIGNAL_LIMIT.max
            ));
        }
    }
    if !temp_c.is_finite() {
        return Err(format!("{temp_field} = {temp_c} is not a finite number"));
    }
    if !TEMP_LIMIT.contains(temp_c) {
        return Err(format!(
            "{temp_field} = {temp_c} °C is outside {} … {} °C: not a sensor's temperature",
            TEMP_LIMIT.min, TEMP_LIMIT.max
        ));
    }
    Ok(())
}

/// Reads a log (ULog or DataFlash, told by its content) from start to end: `on_sample` gets
/// every accelerometer sample with its instance, `on_progress` the bytes read now and then.
/// An error — the file's, a message's, a sample's or `on_sample`'s — ends the pass.
pub fn read(
    path: &Path,
    on_progress: &mut dyn FnMut(u64),
    on_sample: &mut dyn FnMut(&Instance, &Sample) -> Result<(), LogError>,
) -> Result<Summary, LogError> {
    let named = |what: String| LogError { file: path.to_path_buf(), offset: None, message: None, what };
    let f = File::open(path).map_err(|e| named(e.to_string()))?;
    let meta = f.metadata().map_err(|e| named(e.to_string()))?;
    if meta.is_dir() {
        return Err(named("is a directory, not a log".into()));
    }
    let mut file = Src::new(BufReader::with_capacity(1 << 16, f), path);
    let mut head = [0u8; 7];
    let n = file.fill(&mut head)?;
    let format = Format::detect(&head[..n]).ok_or_else(|| {
        let shown: Vec<String> = head[..n].iter().map(|b| format!("{b:02x}")).collect();
        named(format!(
            "not a flight-controller log: it starts with {} (a PX4 ULog starts with `ULog` 01 12 35, an ArduPilot DataFlash log with a3 95)",
            if n == 0 { "nothing (empty file)".to_string() } else { shown.join(" ") }
        ))
    })?;
    // The first bytes again, then the rest of the file.
    let mut src = Src::new(std::io::Cursor::new(head[..n].to_vec()).chain(file.r), path);
    let mut summary = match format {
        Format::ULog => ulog::read(&mut src, on_progress, on_sample)?,
        Format::DataFlash => dataflash::read(&mut src, on_progress, on_sample)?,
    };
    summary.bytes = src.offset;
    if summary.instances.is_empty() {
        let wanted = match format {
            Format::ULog => "no `sensor_accel` sample",
            Format::DataFlash => "no `IMU` sample (IMU, IMU2, IMU3)",
        };
        return Err(named(format!("{wanted} in the log: no accelerometer to import")));
    }
    Ok(summary)
}

/// The format of the file at `path`, by its first bytes (`None`: unreadable or neither).
pub fn format_of(path: &Path) -> Option<Format> {
    let mut head = [0u8; 7];
    let mut f = File::open(path).ok()?;
    let mut n = 0;
    while n < head.len() {
        match f.read(&mut head[n..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => n += k,
        }
    }
    Format::detect(&head[..n])
}

/// Reads a log to its end for its summary alone (every message parsed and checked).
pub fn scan(path: &Path) -> Result<Summary, LogError> {
    read(path, &mut |_| {}, &mut |_, _| Ok(()))
}
