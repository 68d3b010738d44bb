//! Flight-controller logs written byte by byte for the tests, from the formats' descriptions
//! (ArduPilot's `LogStructure.h` FMT/IMU layouts, PX4's ULog file-format page), independent
//! of the readers in `bins_cal::fclog`: a DataFlash log in the old style (`IMU`, `IMU2`,
//! `IMU3` with `TimeMS`, `Temp`) or the new (`IMU` with `TimeUS`, `I`, `T`), and a ULog with
//! `sensor_accel` (a nested type and trailing padding, as PX4 writes it).

#![allow(dead_code)]

/// One accelerometer sample to write: instance, time \[µs\], acceleration \[m/s²\], temperature.
#[derive(Clone, Copy, Debug)]
pub struct S {
    pub instance: u8,
    pub time_us: u64,
    pub accel: [f32; 3],
    pub temp: f32,
}

fn padded(s: &str, n: usize) -> Vec<u8> {
    let mut b = s.as_bytes().to_vec();
    b.resize(n, 0);
    b
}

/// A DataFlash FMT message defining type `ty`.
pub fn df_fmt(ty: u8, len: u8, name: &str, format: &str, columns: &str) -> Vec<u8> {
    let mut m = vec![0xA3, 0x95, 128, ty, len];
    m.extend(padded(name, 4));
    m.extend(padded(format, 16));
    m.extend(padded(columns, 64));
    assert_eq!(m.len(), 89);
    m
}

/// The DataFlash FMT of FMT itself, as ArduPilot writes it first.
pub fn df_fmt_of_fmt() -> Vec<u8> {
    df_fmt(128, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
}

/// A DataFlash log. `new_style`: one `IMU` (type 131) `QBffffffIIfBB` with
/// `TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH`; old style: `IMU`, `IMU2`, `IMU3`
/// (types 131, 135, 149) `IffffffIIf` with `TimeMS,GyrX,…,AccZ,ErrG,ErrA,Temp` (log171's
/// layout), time in ms. A `PARM` message (type 129) is put between, which the reader skips.
pub fn dataflash(new_style: bool, samples: &[S]) -> Vec<u8> {
    let mut out = df_fmt_of_fmt();
    out.extend(df_fmt(129, 27, "PARM", "INf", "TimeMS,Name,Value"));
    if new_style {
        out.extend(df_fmt(
            131,
            3 + 8 + 1 + 24 + 8 + 4 + 2,
            "IMU",
            "QBffffffIIfBB",
            "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH",
        ));
    } else {
        for (ty, name) in [(131, "IMU"), (135, "IMU2"), (149, "IMU3")] {
            out.extend(df_fmt(ty, 43, name, "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"));
        }
    }
    let mut parm = vec![0xA3, 0x95, 129];
    parm.extend(7u32.to_le_bytes());
    parm.extend(padded("INS_ACCOFFS_X", 16));
    parm.extend(0.25f32.to_le_bytes());
    out.extend(parm);
    for s in samples {
        let gyro = [0.001f32, -0.002, 0.003];
        if new_style {
            let mut m = vec![0xA3, 0x95, 131];
            m.extend(s.time_us.to_le_bytes());
            m.push(s.instance);
            gyro.iter().chain(&s.accel).for_each(|v| m.extend(v.to_le_bytes()));
            m.extend(0u32.to_le_bytes());
            m.extend(0u32.to_le_bytes());
            m.extend(s.temp.to_le_bytes());
            m.extend([1u8, 1u8]);
            out.extend(m);
        } else {
            let ty = [131u8, 135, 149][s.instance as usize];
            let mut m = vec![0xA3, 0x95, ty];
            m.extend(((s.time_us / 1000) as u32).to_le_bytes());
            gyro.iter().chain(&s.accel).for_each(|v| m.extend(v.to_le_bytes()));
            m.extend(0u32.to_le_bytes());
            m.extend(0u32.to_le_bytes());
            m.extend(s.temp.to_le_bytes());
            out.extend(m);
        }
    }
    out
}

fn ulog_msg(ty: u8, payload: &[u8]) -> Vec<u8> {
    let mut m = (payload.len() as u16).to_le_bytes().to_vec();
    m.push(ty);
    m.extend_from_slice(payload);
    m
}

/// A ULog: header, flag bits, an information message, the formats of `sensor_accel` (as
/// PX4 1.13 writes it: `timestamp`, `timestamp_sample`, `device_id`, `x`, `y`, `z`,
/// `temperature`, `error_count`, `clip_counter[3]`, `_padding0[5]`, with a nested type put in
/// front for the reader to skip over) and of `vehicle_status`, a parameter; then one `A` per
/// instance (message ids 3 + instance), `vehicle_status` data, a log text and the samples.
/// `with_temperature`: false leaves the field out of the format (renamed `temperatur_`).
pub fn ulog(samples: &[S], with_temperature: bool) -> Vec<u8> {
    let mut out = b"ULog\x01\x12\x35".to_vec();
    out.push(1);
    out.extend(1_000_000u64.to_le_bytes());
    let mut flags = vec![0u8; 40];
    flags[0] = 0; // compat
    out.extend(ulog_msg(b'B', &flags));
    let mut info = vec![b"char[8] sys_name".len() as u8];
    info.extend(b"char[8] sys_name");
    info.extend(padded("PX4", 8));
    out.extend(ulog_msg(b'I', &info));
    out.extend(ulog_msg(b'F', b"vec3:float[3] v;uint8_t[4] _padding0;"));
    let temp = if with_temperature { "temperature" } else { "temperatur_" };
    let accel = format!(
        "sensor_accel:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;float y;float z;float {temp};uint32_t error_count;uint8_t[3] clip_counter;uint8_t[5] _padding0;"
    );
    out.extend(ulog_msg(b'F', accel.as_bytes()));
    out.extend(ulog_msg(b'F', b"vehicle_status:uint64_t timestamp;vec3[2] spare;uint8_t arming_state;"));
    let mut param = vec![b"float CAL_ACC0_XOFF".len() as u8];
    param.extend(b"float CAL_ACC0_XOFF");
    param.extend(0.5f32.to_le_bytes());
    out.extend(ulog_msg(b'P', &param));
    let mut instances: Vec<u8> = samples.iter().map(|s| s.instance).collect();
    instances.sort();
    instances.dedup();
    let mut add = vec![0u8];
    add.extend(1u16.to_le_bytes());
    add.extend(b"vehicle_status");
    out.extend(ulog_msg(b'A', &add));
    for &k in &instances {
        let mut add = vec![k];
        add.extend((3 + k as u16).to_le_bytes());
        add.extend(b"sensor_accel");
        out.extend(ulog_msg(b'A', &add));
    }
    let mut status = 1u16.to_le_bytes().to_vec();
    status.extend(1_500_000u64.to_le_bytes());
    status.extend([0u8; 32]);
    status.push(2);
    out.extend(ulog_msg(b'D', &status));
    let mut text = vec![b'6'];
    text.extend(1_600_000u64.to_le_bytes());
    text.extend(b"[commander] ready");
    out.extend(ulog_msg(b'L', &text));
    for s in samples {
        let mut d = (3 + s.instance as u16).to_le_bytes().to_vec();
        d.extend((s.time_us + 400).to_le_bytes());
        d.extend(s.time_us.to_le_bytes());
        d.extend((2_424_842u32 + s.instance as u32).to_le_bytes());
        s.accel.iter().for_each(|v| d.extend(v.to_le_bytes()));
        d.extend(s.temp.to_le_bytes());
        d.extend(0u32.to_le_bytes());
        d.extend([0u8, 0, 0]);
        // The trailing _padding0 is not logged.
        out.extend(ulog_msg(b'D', &d));
    }
    let mut sync = vec![0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12];
    out.extend(ulog_msg(b'S', &std::mem::take(&mut sync)));
    out
}

/// `n` samples per instance of `instances`, at `rate_hz`, with a temperature ramp and a
/// smooth acceleration (f32 values the tests compare exactly).
pub fn samples(instances: &[u8], n: usize, rate_hz: f64) -> Vec<S> {
    let mut v = Vec::new();
    for k in 0..n {
        for &i in instances {
            let t = k as f64 / rate_hz;
            v.push(S {
                instance: i,
                time_us: 10_000_000 + (t * 1e6).round() as u64,
                accel: [
                    (0.1 * t).sin() as f32 * 0.3 + i as f32 * 0.01,
                    -0.2 + (0.05 * t).cos() as f32 * 0.1,
                    -9.80665 + 0.001 * k as f32,
                ],
                temp: 25.0 + 0.01 * k as f32 + i as f32,
            });
        }
    }
    v
}
