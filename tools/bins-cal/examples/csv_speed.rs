//! Reading speed of a recording: `recording::Reader` (the `csv` crate fed line by line, with
//! the format's checks) against a bare pass of the `csv` crate doing the same work short of the
//! checks (cells trimmed, the 16 numbers parsed, `pos` kept), on a generated file of every
//! column. Best of five passes each over the file, warm page cache.
//!
//! `cargo run --release -p bins-cal --example csv_speed [ROWS]` (default 300 000)

use bins_cal::recording::{Columns, Reader, Row, VibKind, Writer};
use std::io::BufReader;
use std::time::{Duration, Instant};

fn main() {
    let rows: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(300_000);
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("speed.csv");
    let file = std::fs::File::create(&path).expect("the file");
    let mut w = Writer::new(std::io::BufWriter::new(file), &path, Columns::all(), &["speed test"]).unwrap();
    let mut row = Row::default();
    for k in 0..rows {
        let x = k as f64;
        row.t_s = 0.001 * x;
        row.u_v = [0.55 * (x * 1e-3).sin(), -0.55 * (x * 7e-4).cos(), 0.001 + 1e-6 * x.sqrt()];
        row.temp_c = 20.0 + 25.0 * (x * 1e-5).sin();
        row.f_g = [Some(0.0), Some(-std::f64::consts::FRAC_1_SQRT_2), Some(std::f64::consts::FRAC_1_SQRT_2)];
        row.vib_kind = Some(VibKind::Sine);
        row.vib_g = [Some(0.42), Some(0.8), Some(1.5)];
        row.vib_hz = Some(16.0);
        row.vib_bw_hz = None;
        row.chamber_c = Some(20.5);
        row.pos = Some(format!("TP{}", 1 + k % 6));
        row.power_s = Some(3600.0 + 0.001 * x);
        w.write_row(&row).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::metadata(&path).unwrap().len() as f64;

    let ours = best_of(5, || {
        let mut r = Reader::open(&path).unwrap();
        let mut row = Row::default();
        let mut sum = 0.0;
        while r.read_row(&mut row).unwrap() {
            sum += row.u_v[0] + row.pos.as_ref().map_or(0, String::len) as f64;
        }
        sum
    });
    let csv = best_of(5, || {
        let f = std::fs::File::open(&path).unwrap();
        let mut r = csv::ReaderBuilder::new()
            .has_headers(false)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(BufReader::with_capacity(1 << 16, f));
        let mut rec = csv::ByteRecord::new();
        r.read_byte_record(&mut rec).unwrap();
        let header: Vec<String> = rec.iter().map(|c| String::from_utf8_lossy(c).into_owned()).collect();
        let pos_col = header.iter().position(|h| h == "pos").unwrap();
        let (mut sum, mut pos) = (0.0, String::new());
        let mut v = [0.0f64; 17];
        while r.read_byte_record(&mut rec).unwrap() {
            for (i, cell) in rec.iter().enumerate() {
                let s = std::str::from_utf8(cell).unwrap();
                if i == pos_col {
                    pos.clear();
                    pos.push_str(s);
                } else if !s.is_empty() && i != 8 {
                    v[i] = s.parse().unwrap();
                }
            }
            sum += v[1] + pos.len() as f64;
        }
        sum
    });
    let mb = bytes / 1e6;
    println!("{rows} rows, {mb:.1} MB, every column of the format");
    for (name, d) in [("recording::Reader", ours), ("csv crate (ByteRecord, trimmed, numbers parsed)", csv)] {
        let s = d.as_secs_f64();
        println!("{name:>50}: {:.3} s, {:.0} MB/s, {:.2} M rows/s", s, mb / s, rows as f64 / s / 1e6);
    }
    println!("csv crate time / recording::Reader time: {:.2}", csv.as_secs_f64() / ours.as_secs_f64());
}

fn best_of(n: usize, mut f: impl FnMut() -> f64) -> Duration {
    let mut best = Duration::MAX;
    for _ in 0..n {
        let t = Instant::now();
        std::hint::black_box(f());
        best = best.min(t.elapsed());
    }
    best
}
