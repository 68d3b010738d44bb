//! ArduPilot DataFlash logs (`.bin`), read in a stream for the `IMU` messages.
//!
//! A message is the header 0xA3 0x95, a type byte, and a payload whose length and layout the
//! log defines itself in `FMT` messages (type 128: `Type`, `Length`, `Name` char\[4\], `Format`
//! char\[16\], `Columns` char\[64\]; `Length` counts the 3 header bytes). Every message is read
//! whole and checked: a header that is not 0xA3 0x95, a type no `FMT` defined, a message cut
//! off by the end of the file, or an `FMT` whose format does not add up to its length is an
//! error naming the byte offset and the message.
//!
//! The accelerometer comes in `IMU` messages, in two styles: old (ArduCopter ≤ 4.0) with one
//! message name per instance (`IMU`, `IMU2`, `IMU3`) and time `TimeMS` \[ms\] or `TimeUS`
//! \[µs\], temperature `Temp` or `T`; new (4.1 on) one `IMU` with the instance in field `I`,
//! time `TimeUS`, temperature `T`. `AccX`, `AccY`, `AccZ` \[m/s²\] are what the autopilot
//! publishes: after its sensor rotation, its temperature calibration (`INS_TCAL*`), its
//! offsets and scale factors (`INS_ACC*OFFS`, `INS_ACC*SCAL`) and its board orientation
//! (`AHRS_ORIENTATION`), low-pass filtered, in the body frame.

use super::{Format, Instance, LogError, Sample, Src, Summary, check_sample};
use std::io::Read;

/// The two bytes every message starts with.
pub const HEADER: [u8; 2] = [0xA3, 0x95];
/// The type of `FMT` messages.
pub const FMT_TYPE: u8 = 128;
/// The length of an `FMT` message, header included \[B\].
pub const FMT_LENGTH: usize = 89;

/// The size of a field of DataFlash format character `c` \[B\], or `None` for a character the
/// format does not define.
pub fn field_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' | b'g' => 2,
        b'i' | b'I' | b'f' | b'e' | b'E' | b'L' | b'n' => 4,
        b'd' | b'q' | b'Q' => 8,
        b'N' => 16,
        b'Z' | b'a' => 64,
        _ => return None,
    })
}

/// A numeric field: where it is in the payload and how it is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Field {
    offset: usize,
    kind: u8,
}

impl Field {
    /// The value of the field in `payload` (the message without its 3 header bytes), in the
    /// unit the format gives it (`c`, `C`, `e`, `E` are hundredths).
    fn value(&self, payload: &[u8]) -> Option<f64> {
        let b = |n: usize| payload.get(self.offset..self.offset + n);
        Some(match self.kind {
            b'f' => f32::from_le_bytes(b(4)?.try_into().ok()?) as f64,
            b'd' => f64::from_le_bytes(b(8)?.try_into().ok()?),
            b'b' => i8::from_le_bytes(b(1)?.try_into().ok()?) as f64,
            b'B' | b'M' => b(1)?[0] as f64,
            b'h' => i16::from_le_bytes(b(2)?.try_into().ok()?) as f64,
            b'H' => u16::from_le_bytes(b(2)?.try_into().ok()?) as f64,
            b'i' => i32::from_le_bytes(b(4)?.try_into().ok()?) as f64,
            b'I' => u32::from_le_bytes(b(4)?.try_into().ok()?) as f64,
            b'q' => i64::from_le_bytes(b(8)?.try_into().ok()?) as f64,
            b'Q' => u64::from_le_bytes(b(8)?.try_into().ok()?) as f64,
            b'c' => i16::from_le_bytes(b(2)?.try_into().ok()?) as f64 * 0.01,
            b'C' => u16::from_le_bytes(b(2)?.try_into().ok()?) as f64 * 0.01,
            b'e' => i32::from_le_bytes(b(4)?.try_into().ok()?) as f64 * 0.01,
            b'E' => u32::from_le_bytes(b(4)?.try_into().ok()?) as f64 * 0.01,
            _ => return None,
        })
    }

    /// The field as an unsigned integer time (`Q`, `I`, `H`, `B`), exactly.
    fn time(&self, payload: &[u8]) -> Option<u64> {
        let b = |n: usize| payload.get(self.offset..self.offset + n);
        Some(match self.kind {
            b'Q' => u64::from_le_bytes(b(8)?.try_into().ok()?),
            b'I' => u32::from_le_bytes(b(4)?.try_into().ok()?) as u64,
            b'H' => u16::from_le_bytes(b(2)?.try_into().ok()?) as u64,
            b'B' => b(1)?[0] as u64,
            _ => return None,
        })
    }
}

/// Where an `IMU` message's fields are.
#[derive(Clone, Debug)]
struct ImuLayout {
    /// The instance of an old-style message (`IMU` 0, `IMU2` 1, `IMU3` 2); `None`: field `I`.
    fixed_instance: Option<u8>,
    instance: Option<Field>,
    time: Field,
    /// µs per unit of the time field (1000 for `TimeMS`, 1 for `TimeUS`).
    time_scale_us: u64,
    accel: [Field; 3],
    temp: Field,
    time_name: String,
    temp_name: String,
}

/// One message type the log defined.
#[derive(Clone, Debug)]
struct Def {
    length: usize,
    name: String,
    imu: Option<ImuLayout>,
}

/// The text of a zero-padded char field.
fn text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).trim().to_string()
}

/// The instance of an old-style IMU message name.
fn imu_name(name: &str) -> Option<Option<u8>> {
    match name {
        "IMU" => Some(None),
        "IMU2" => Some(Some(1)),
        "IMU3" => Some(Some(2)),
        _ => None,
    }
}

/// The layout of the `IMU` message defined by an `FMT` payload; errors say what is missing.
fn imu_layout(name: &str, format: &str, columns: &[&str], has_i: bool) -> Result<ImuLayout, String> {
    let mut offsets = Vec::with_capacity(format.len());
    let mut at = 0;
    for c in format.bytes() {
        offsets.push(Field { offset: at, kind: c });
        at += field_size(c).ok_or_else(|| format!("format character `{}` unknown", c as char))?;
    }
    let find = |names: &[&str]| {
        names.iter().find_map(|n| columns.iter().position(|c| c == n).map(|k| (offsets[k], n.to_string())))
    };
    let (time, time_name) =
        find(&["TimeUS", "TimeMS"]).ok_or_else(|| "no time field (TimeUS or TimeMS)".to_string())?;
    if !matches!(time.kind, b'Q' | b'I' | b'H' | b'B') {
        return Err(format!("time field {time_name} of format `{}`, not an unsigned integer", time.kind as char));
    }
    let mut accel = [Field { offset: 0, kind: b'f' }; 3];
    for (k, n) in ["AccX", "AccY", "AccZ"].iter().enumerate() {
        accel[k] = find(&[n]).ok_or_else(|| format!("no field {n}: not an accelerometer message"))?.0;
    }
    let (temp, temp_name) = find(&["T", "Temp"]).ok_or_else(|| {
        "no temperature field (T or Temp): the import needs the accelerometer's temperature".to_string()
    })?;
    let instance = if has_i { find(&["I"]).map(|f| f.0) } else { None };
    let fixed_instance = match (imu_name(name).flatten(), instance) {
        (Some(k), _) => Some(k),
        (None, Some(_)) => None,
        (None, None) => Some(0),
    };
    Ok(ImuLayout {
        fixed_instance,
        instance,
        time,
        time_scale_us: if time_name == "TimeMS" { 1000 } else { 1 },
        accel,
        temp,
        time_name,
        temp_name,
    })
}

/// Reads a DataFlash log whose first `head.len()` bytes are `head` and the rest is in `src`.
pub(crate) fn read<R: Read>(
    src: &mut Src<R>,
    on_progress: &mut dyn FnMut(u64),
    on_sample: &mut dyn FnMut(&Instance, &Sample) -> Result<(), LogError>,
) -> Result<Summary, LogError> {
    let mut defs: Vec<Option<Def>> = vec![None; 256];
    defs[FMT_TYPE as usize] = Some(Def { length: FMT_LENGTH, name: "FMT".into(), imu: None });
    let mut summary =
        Summary { format: Format::DataFlash, instances: Vec::new(), samples: Vec::new(), messages: 0, bytes: 0 };
    let mut msg = [0u8; 256];
    let mut last_time: Vec<Option<u64>> = Vec::new();
    let mut prev: Option<(u64, String)> = None;
    loop {
        let at = src.offset;
        let got = src.fill(&mut msg[..3])?;
        if got == 0 {
            break;
        }
        let after = || prev.as_ref().map_or(String::new(), |(o, n)| format!(" (after {n} at byte {o})"));
        if got < 3 {
            return Err(src.error(
                Some(at),
                None,
                format!("message header cut off: {got} of 3 bytes (truncated log?)"),
            ));
        }
        if msg[..2] != HEADER {
            return Err(src.error(
                Some(at),
                None,
                format!("no message header here: {:02x} {:02x}, not a3 95{} (corrupted log)", msg[0], msg[1], after()),
            ));
        }
        let ty = msg[2];
        let Some(def) = defs[ty as usize].as_ref() else {
            return Err(src.error(
                Some(at),
                None,
                format!("message type {ty} has no FMT definition{} (corrupted log)", after()),
            ));
        };
        let (length, name) = (def.length, def.name.clone());
        let have = 3 + src.fill(&mut msg[3..length])?;
        if have < length {
            return Err(src.error(
                Some(at),
                Some(&name),
                format!("cut off: {have} of its {length} bytes before the end of the file (truncated log?)"),
            ));
        }
        summary.messages += 1;
        let payload = &msg[3..length];
        if ty == FMT_TYPE {
            let (t, len) = (payload[0], payload[1] as usize);
            let name = text(&payload[2..6]);
            let format = text(&payload[6..22]);
            let columns_text = text(&payload[22..86]);
            if len < 3 || (t == FMT_TYPE && len != FMT_LENGTH) {
                return Err(src.error(
                    Some(at),
                    Some(&format!("FMT of {name}")),
                    format!("length {len} (corrupted log)"),
                ));
            }
            let imu = if imu_name(&name).is_some() {
                let columns: Vec<&str> = columns_text.split(',').collect();
                let size: Option<usize> = format.bytes().map(field_size).sum();
                if size.is_none_or(|s| s + 3 != len) || columns.len() != format.len() {
                    return Err(src.error(
                        Some(at),
                        Some(&format!("FMT of {name}")),
                        format!(
                            "format `{format}` ({} columns) does not fill its length {len} (corrupted log)",
                            columns.len()
                        ),
                    ));
                }
                let has_i = columns.contains(&"I");
                match imu_layout(&name, &format, &columns, has_i) {
                    Ok(l) => Some(l),
                    Err(e) if e.starts_with("no field Acc") => None,
                    Err(e) => return Err(src.error(Some(at), Some(&format!("FMT of {name}")), e)),
                }
            } else {
                None
            };
            defs[t as usize] = Some(Def { length: len, name, imu });
        } else if let Some(l) = &def.imu {
            let index = match (l.fixed_instance, l.instance) {
                (Some(k), _) => k,
                (None, Some(f)) => f.value(payload).unwrap_or(0.0) as u8,
                (None, None) => 0,
            };
            let Some(t) = l.time.time(payload) else {
                return Err(src.error(Some(at), Some(&name), "time field unreadable"));
            };
            let accel = l.accel.map(|f| f.value(payload).unwrap_or(f64::NAN));
            let temp_c = l.temp.value(payload).unwrap_or(f64::NAN);
            let time_us = t.saturating_mul(l.time_scale_us);
            check_sample(&accel, ["AccX", "AccY", "AccZ"], temp_c, &l.temp_name)
                .map_err(|e| src.error(Some(at), Some(&name), e))?;
            let pos = match summary.position(index) {
                Some(p) => p,
                None => {
                    summary.instances.push(Instance {
                        index,
                        message: name.clone(),
                        time_field: l.time_name.clone(),
                        temp_field: l.temp_name.clone(),
                        device_id: None,
                    });
                    summary.samples.push(0);
                    last_time.push(None);
                    summary.instances.len() - 1
                }
            };
            if let Some(prev_t) = last_time[pos]
                && time_us <= prev_t
            {
                return Err(src.error(
                    Some(at),
                    Some(&name),
                    format!(
                        "{} = {} does not increase (instance {index}'s previous sample: {}): the log's clock went back or a message is corrupted",
                        l.time_name,
                        t,
                        prev_t / l.time_scale_us
                    ),
                ));
            }
            last_time[pos] = Some(time_us);
            summary.samples[pos] += 1;
            let s = Sample { instance: index, time_us, accel_m_s2: accel, temp_c, offset: at };
            on_sample(&summary.instances[pos], &s)?;
        }
        prev = Some((at, name));
        if summary.messages.is_multiple_of(1 << 14) {
            on_progress(src.offset);
        }
    }
    on_progress(src.offset);
    Ok(summary)
}
