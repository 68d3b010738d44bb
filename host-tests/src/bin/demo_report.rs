//! Prints the demo's table from the firmware's results: `demo-report IN.bin OUT.bin`, where
//! IN is what `gen-vectors --demo` wrote and OUT what the firmware wrote back for it. Checks
//! that every firmware result equals the host's bit for bit, then prints the |g| error of
//! T(13) per check position, temperature and method.

use bins_comp::vectors::{self, RECORD_BYTES, RESULT_BYTES, Record};
use bins_comp::{Sample, Status};

const METHODS: [&str; 5] = ["T0 consts", "method 1", "m2 simpl.", "m2 full", "m2 linear"];

fn read(path: &str) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| {
        eprintln!("demo-report: {path}: {e}");
        std::process::exit(1)
    })
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [inp, out] = args.as_slice() else {
        eprintln!("usage: demo-report IN.bin OUT.bin");
        std::process::exit(2);
    };
    let (inb, outb) = (read(inp), read(out));
    if inb.len() % RECORD_BYTES != 0 || outb.len() != inb.len() / RECORD_BYTES * RESULT_BYTES {
        eprintln!(
            "demo-report: {out}: {} bytes do not match the {} records of {inp}",
            outb.len(),
            inb.len() / RECORD_BYTES
        );
        std::process::exit(1);
    }
    let mut rows = Vec::new();
    let mut mismatches = 0;
    for (ri, ro) in inb.chunks_exact(RECORD_BYTES).zip(outb.chunks_exact(RESULT_BYTES)) {
        let rec = Record::decode(ri.try_into().expect("record size"));
        let w = |k: usize| f32::from_le_bytes(ro[4 * k..4 * k + 4].try_into().expect("4 bytes"));
        let fw = Sample {
            accel_g: [w(0), w(1), w(2)],
            status: Status(u32::from_le_bytes(ro[12..16].try_into().expect("4 bytes"))),
        };
        if !vectors::bit_identical(&fw, &rec.expected) {
            mismatches += 1;
        }
        let a = fw.accel_g.map(|x| x as f64);
        rows.push((rec.temp_c, (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt() - 1.0, fw.status));
    }
    println!("The paper's unit: true constants = the quadratic in T through Tables T1/T2;");
    println!("calibration = the paper's two-range piecewise-linear model (knots -40, +20, +70 °C).");
    println!("|g| error of T(13) in mg, computed by the firmware in QEMU, six check positions (θ = 25°):\n");
    let per_t = 6 * METHODS.len();
    for block in rows.chunks(per_t) {
        println!("T = {:+.0} °C   {}", block[0].0, METHODS.map(|m| format!("{m:>10}")).join(""));
        let mut worst = [0.0f64; 5];
        for (p, pos) in block.chunks(METHODS.len()).enumerate() {
            let cells: Vec<String> = pos.iter().map(|r| format!("{:>10.3}", r.1 * 1e3)).collect();
            for (m, r) in pos.iter().enumerate() {
                worst[m] = worst[m].max(r.1.abs());
                assert_eq!(r.2, Status::OK, "unexpected status");
            }
            println!("  CP{}         {}", p + 1, cells.join(""));
        }
        println!("  max |Δg|    {}", worst.map(|w| format!("{:>10.3}", w * 1e3)).join(""));
        if worst[0] > 1e-6 {
            let factor =
                worst.map(|w| if w > 0.0 { format!("{:>9.1}×", worst[0] / w) } else { format!("{:>10}", "-") });
            println!("  reduction   {}", factor.join(""));
        }
        println!();
    }
    println!("firmware vs host f32: {} of {} results bit-identical", rows.len() - mismatches, rows.len());
    if mismatches > 0 {
        std::process::exit(1);
    }
}
