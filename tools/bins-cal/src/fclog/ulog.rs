//! PX4 ULog files (`.ulg`), read in a stream for the `sensor_accel` topic.
//!
//! The file is a 16-byte header (`ULog` 0x01 0x12 0x35, a version byte, the start time in
//! µs), then messages: a 2-byte payload size, a type byte, the payload. The definitions
//! (`F` formats `name:type field;…`, `I`/`M` information, `P`/`Q` parameters, `B` flag bits)
//! come first; in the data, `A` subscribes a topic instance (`multi_id`) to a message id and
//! `D` carries one sample of it (the id, then the fields in the order of the format, nested
//! types inlined, trailing `_padding` fields left out). `L`/`C` log text, `S` sync, `O`
//! dropouts and `R` unsubscriptions carry nothing the import needs. Every message is read
//! whole and checked: a type the format does not define, a message cut off by the end of the
//! file, a `D` of an id no `A` subscribed, a `sensor_accel` sample shorter than its format,
//! incompatible flag bits this reader does not know: an error naming the byte offset.
//!
//! `sensor_accel` holds what the driver publishes, before the calibration: `x`, `y`, `z`
//! \[m/s²\] in the sensor's frame after the driver's own rotation of the chip, `temperature`
//! [°C], `device_id` (the key of `CAL_ACC*_ID` and `TC_A*_ID`), `timestamp` and
//! `timestamp_sample` \[µs since boot\]. The thermal offsets (`TC_A*`) and the calibration
//! (`CAL_ACC*`) are applied downstream of it (PX4 `src/lib/sensor_calibration/`).

use super::{Format, Instance, LogError, Sample, Src, Summary, check_sample};
use std::collections::HashMap;
use std::io::Read;

/// The first 7 bytes of a ULog file.
pub const MAGIC: &[u8] = b"ULog\x01\x12\x35";
/// The topic the import reads.
pub const ACCEL_TOPIC: &str = "sensor_accel";

/// The size of a ULog basic type \[B\], or `None` for a name that is not one.
pub fn basic_size(t: &str) -> Option<usize> {
    Some(match t {
        "int8_t" | "uint8_t" | "bool" | "char" => 1,
        "int16_t" | "uint16_t" => 2,
        "int32_t" | "uint32_t" | "float" => 4,
        "int64_t" | "uint64_t" | "double" => 8,
        _ => return None,
    })
}

/// One field of a format: its type, array length (0: not an array) and name.
#[derive(Clone, Debug, PartialEq, Eq)]
struct FieldDef {
    ty: String,
    len: usize,
    name: String,
}

/// Parses `type name` or `type[N] name`.
fn parse_field(f: &str) -> Option<FieldDef> {
    let (ty, name) = f.trim().split_once(' ')?;
    let (ty, len) = match ty.split_once('[') {
        Some((t, n)) => (t, n.strip_suffix(']')?.parse().ok()?),
        None => (ty, 0),
    };
    Some(FieldDef { ty: ty.to_string(), len, name: name.trim().to_string() })
}

/// The size of type `ty` \[B\]: a basic type, or a format of the log (nested types inlined,
/// their padding included), at most 8 levels deep.
fn type_size(ty: &str, formats: &HashMap<String, Vec<FieldDef>>, depth: u32) -> Option<usize> {
    if let Some(s) = basic_size(ty) {
        return Some(s);
    }
    if depth > 8 {
        return None;
    }
    formats.get(ty)?.iter().map(|f| Some(type_size(&f.ty, formats, depth + 1)? * f.len.max(1))).sum()
}

/// A basic field of a topic's sample: offset in the sample (after the message id) and type.
#[derive(Clone, Debug)]
struct Field {
    offset: usize,
    ty: String,
}

impl Field {
    fn value(&self, b: &[u8]) -> Option<f64> {
        let at = |n: usize| b.get(self.offset..self.offset + n);
        Some(match self.ty.as_str() {
            "float" => f32::from_le_bytes(at(4)?.try_into().ok()?) as f64,
            "double" => f64::from_le_bytes(at(8)?.try_into().ok()?),
            "int8_t" => i8::from_le_bytes(at(1)?.try_into().ok()?) as f64,
            "uint8_t" | "bool" => at(1)?[0] as f64,
            "int16_t" => i16::from_le_bytes(at(2)?.try_into().ok()?) as f64,
            "uint16_t" => u16::from_le_bytes(at(2)?.try_into().ok()?) as f64,
            "int32_t" => i32::from_le_bytes(at(4)?.try_into().ok()?) as f64,
            "uint32_t" => u32::from_le_bytes(at(4)?.try_into().ok()?) as f64,
            "int64_t" => i64::from_le_bytes(at(8)?.try_into().ok()?) as f64,
            "uint64_t" => u64::from_le_bytes(at(8)?.try_into().ok()?) as f64,
            _ => return None,
        })
    }

    fn uint(&self, b: &[u8]) -> Option<u64> {
        let at = |n: usize| b.get(self.offset..self.offset + n);
        Some(match self.ty.as_str() {
            "uint64_t" => u64::from_le_bytes(at(8)?.try_into().ok()?),
            "uint32_t" => u32::from_le_bytes(at(4)?.try_into().ok()?) as u64,
            _ => return None,
        })
    }
}

/// Where the fields of a `sensor_accel` sample are.
#[derive(Clone, Debug)]
struct AccelLayout {
    time: Field,
    time_name: &'static str,
    device_id: Option<Field>,
    accel: [Field; 3],
    temp: Field,
    /// The bytes a sample must have: up to the end of its last field that is not padding.
    min_size: usize,
}

/// The layout of `sensor_accel` in the log's formats; errors say what is missing.
fn accel_layout(formats: &HashMap<String, Vec<FieldDef>>) -> Result<AccelLayout, String> {
    let fields = formats.get(ACCEL_TOPIC).ok_or("no format definition of sensor_accel")?;
    let mut at = 0;
    let mut found: HashMap<&str, Field> = HashMap::new();
    let mut min_size = 0;
    for f in fields {
        let size = type_size(&f.ty, formats, 0).ok_or_else(|| format!("field {} of unknown type {}", f.name, f.ty))?;
        if f.len == 0 && basic_size(&f.ty).is_some() {
            found.insert(f.name.as_str(), Field { offset: at, ty: f.ty.clone() });
        }
        at += size * f.len.max(1);
        if !f.name.starts_with("_padding") {
            min_size = at;
        }
    }
    let get = |n: &str| found.get(n).cloned();
    let (time, time_name) = match (get("timestamp_sample"), get("timestamp")) {
        (Some(t), _) => (t, "timestamp_sample"),
        (None, Some(t)) => (t, "timestamp"),
        _ => return Err("no timestamp field".into()),
    };
    if time.ty != "uint64_t" {
        return Err(format!("{time_name} is {}, not uint64_t", time.ty));
    }
    let accel = [get("x"), get("y"), get("z")];
    let [Some(x), Some(y), Some(z)] = accel else { return Err("no x, y, z fields".into()) };
    let temp = get("temperature").ok_or("no temperature field: the import needs the accelerometer's temperature")?;
    Ok(AccelLayout { time, time_name, device_id: get("device_id"), accel: [x, y, z], temp, min_size })
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

/// Reads a ULog file from `src` (at its start).
pub(crate) fn read<R: Read>(
    src: &mut Src<R>,
    on_progress: &mut dyn FnMut(u64),
    on_sample: &mut dyn FnMut(&Instance, &Sample) -> Result<(), LogError>,
) -> Result<Summary, LogError> {
    let mut header = [0u8; 16];
    let n = src.fill(&mut header)?;
    if n < 16 {
        return Err(src.error(Some(0), None, format!("file header cut off: {n} of 16 bytes (truncated log?)")));
    }
    let mut summary =
        Summary { format: Format::ULog, instances: Vec::new(), samples: Vec::new(), messages: 0, bytes: 0 };
    let mut formats: HashMap<String, Vec<FieldDef>> = HashMap::new();
    let mut layout: Option<Result<AccelLayout, String>> = None;
    // msg_id → Some(multi_id) for sensor_accel, None for other topics.
    let mut subscribed: HashMap<u16, Option<u8>> = HashMap::new();
    let mut last_time: Vec<Option<u64>> = Vec::new();
    let mut payload = vec![0u8; u16::MAX as usize];
    let mut prev: Option<(u64, u8)> = None;
    loop {
        let at = src.offset;
        let mut head = [0u8; 3];
        let got = src.fill(&mut head)?;
        if got == 0 {
            break;
        }
        let after = || prev.map_or(String::new(), |(o, t)| format!(" (after `{}` at byte {o})", t as char));
        if got < 3 {
            return Err(src.error(
                Some(at),
                None,
                format!("message header cut off: {got} of 3 bytes (truncated log?)"),
            ));
        }
        let (size, ty) = (u16_at(&head, 0) as usize, head[2]);
        if !b"BFIMPQADRLCSO".contains(&ty) {
            return Err(src.error(
                Some(at),
                None,
                format!("message type 0x{ty:02x} is not a ULog message{} (corrupted log)", after()),
            ));
        }
        let have = src.fill(&mut payload[..size])?;
        let kind = format!("`{}` message", ty as char);
        if have < size {
            return Err(src.error(
                Some(at),
                Some(&kind),
                format!("cut off: {have} of its {size} bytes before the end of the file (truncated log?)"),
            ));
        }
        let p = &payload[..size];
        summary.messages += 1;
        let corrupt = |what: &str| src.error(Some(at), Some(&kind), format!("{what} (corrupted log)"));
        match ty {
            b'B' => {
                if size < 40 {
                    return Err(corrupt(&format!("flag bits of {size} bytes, not 40")));
                }
                let incompat = &p[8..16];
                if incompat[0] & 1 != 0 {
                    return Err(src.error(
                        Some(at),
                        Some(&kind),
                        "the log has data appended after its end (incompatible flag DATA_APPENDED): not read by this tool",
                    ));
                }
                if incompat[0] & !1 != 0 || incompat[1..].iter().any(|&b| b != 0) {
                    return Err(src.error(
                        Some(at),
                        Some(&kind),
                        "incompatible flag bits this reader does not know: a newer ULog version",
                    ));
                }
            }
            b'F' => {
                let text = std::str::from_utf8(p).map_err(|_| corrupt("format not UTF-8"))?;
                let (name, fields) = text.split_once(':').ok_or_else(|| corrupt("format without `:`"))?;
                let fields: Option<Vec<FieldDef>> =
                    fields.split(';').filter(|f| !f.trim().is_empty()).map(parse_field).collect();
                let fields = fields.ok_or_else(|| corrupt(&format!("format of {name}: a field is not `type name`")))?;
                formats.insert(name.to_string(), fields);
            }
            b'A' => {
                if size < 4 {
                    return Err(corrupt("subscription shorter than 4 bytes"));
                }
                let (multi_id, msg_id) = (p[0], u16_at(p, 1));
                let name = String::from_utf8_lossy(&p[3..]).to_string();
                if name == ACCEL_TOPIC {
                    let l = layout.get_or_insert_with(|| accel_layout(&formats));
                    if let Err(e) = l {
                        return Err(src.error(Some(at), Some(ACCEL_TOPIC), e.clone()));
                    }
                    subscribed.insert(msg_id, Some(multi_id));
                } else {
                    subscribed.insert(msg_id, None);
                }
            }
            b'R' => {
                if size < 2 {
                    return Err(corrupt("unsubscription shorter than 2 bytes"));
                }
                subscribed.remove(&u16_at(p, 0));
            }
            b'D' => {
                if size < 2 {
                    return Err(corrupt("data shorter than its 2-byte message id"));
                }
                let msg_id = u16_at(p, 0);
                let Some(sub) = subscribed.get(&msg_id) else {
                    return Err(corrupt(&format!("data of message id {msg_id}, which no `A` message subscribed")));
                };
                let (Some(multi_id), Some(Ok(l))) = (sub, &layout) else {
                    continue_progress(&summary, src, on_progress);
                    prev = Some((at, ty));
                    continue;
                };
                let data = &p[2..];
                if data.len() < l.min_size {
                    return Err(src.error(
                        Some(at),
                        Some(ACCEL_TOPIC),
                        format!("sample of {} bytes, its format needs {} (corrupted log)", data.len(), l.min_size),
                    ));
                }
                let time_us = l.time.uint(data).unwrap_or(0);
                let accel = l.accel.clone().map(|f| f.value(data).unwrap_or(f64::NAN));
                let temp_c = l.temp.value(data).unwrap_or(f64::NAN);
                let device_id = l.device_id.as_ref().and_then(|f| f.uint(data)).map(|d| d as u32);
                check_sample(&accel, ["x", "y", "z"], temp_c, "temperature")
                    .map_err(|e| src.error(Some(at), Some(&format!("{ACCEL_TOPIC} {multi_id}")), e))?;
                let pos = match summary.position(*multi_id) {
                    Some(k) => k,
                    None => {
                        summary.instances.push(Instance {
                            index: *multi_id,
                            message: ACCEL_TOPIC.to_string(),
                            time_field: l.time_name.to_string(),
                            temp_field: "temperature".to_string(),
                            device_id,
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
                        Some(&format!("{ACCEL_TOPIC} {multi_id}")),
                        format!(
                            "{} = {time_us} µs does not increase (the previous sample's: {prev_t} µs): the log's clock went back or a message is corrupted",
                            l.time_name
                        ),
                    ));
                }
                last_time[pos] = Some(time_us);
                summary.samples[pos] += 1;
                let s = Sample { instance: *multi_id, time_us, accel_m_s2: accel, temp_c, offset: at };
                on_sample(&summary.instances[pos], &s)?;
            }
            _ => {}
        }
        continue_progress(&summary, src, on_progress);
        prev = Some((at, ty));
    }
    on_progress(src.offset);
    if let Some(Err(e)) = layout {
        return Err(src.error(None, Some(ACCEL_TOPIC), e));
    }
    Ok(summary)
}

/// Reports the bytes read every 16 384 messages.
fn continue_progress<R>(summary: &Summary, src: &Src<R>, on_progress: &mut dyn FnMut(u64)) {
    if summary.messages.is_multiple_of(1 << 14) {
        on_progress(src.offset);
    }
}
