//! Shared helpers of the host tests: independent f64 references (written here, not taken
//! from the core), random inputs and the paper's data files.

use bins_comp::{Constants, Mat3, Vec3};

/// Path of a file in the repository's `data/` folder (the papers' tables as CSV).
pub fn shared_data(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(name)
}

/// A numeric table of `data/` (the papers' tables), read by the `csv` crate: `#` lines are
/// comments, the first other line is the header, columns are found by name.
pub struct CsvTable {
    /// The header names.
    pub header: Vec<String>,
    /// The rows' numbers.
    pub rows: Vec<Vec<f64>>,
}

impl CsvTable {
    /// Reads the table `data/name`; panics naming the file, line and cell on a cell that is
    /// not a number.
    pub fn read(name: &str) -> CsvTable {
        let path = shared_data(name);
        let mut r = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_path(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let header =
            r.headers().unwrap_or_else(|e| panic!("{}: {e}", path.display())).iter().map(String::from).collect();
        let rows = r
            .records()
            .map(|rec| {
                let rec = rec.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                let line = rec.position().map_or(0, csv::Position::line);
                rec.iter()
                    .map(|c| c.parse().unwrap_or_else(|_| panic!("{}:{line}: `{c}` is not a number", path.display())))
                    .collect()
            })
            .collect();
        CsvTable { header, rows }
    }

    /// The number in column `name` of `row`.
    pub fn get(&self, row: &[f64], name: &str) -> f64 {
        row[self.header.iter().position(|h| h == name).unwrap_or_else(|| panic!("column {name}"))]
    }
}

/// Reads `paper-constants.csv`: (temperature, constants) per row.
pub fn read_paper_constants_csv() -> Vec<(f64, Constants<f64>)> {
    let t = CsvTable::read("paper-constants.csv");
    let names = [["Kxx", "Kxy", "Kxz"], ["Kyx", "Kyy", "Kyz"], ["Kzx", "Kzy", "Kzz"]];
    t.rows
        .iter()
        .map(|r| {
            let k = names.map(|row| row.map(|n| t.get(r, n)));
            let u0 = ["U0x", "U0y", "U0z"].map(|n| t.get(r, n));
            (t.get(r, "temp_C"), Constants { k_v_per_g: k, u0_v: u0 })
        })
        .collect()
}

/// Inverse of a 3×3 matrix by Gauss–Jordan with full pivoting (independent of the core's
/// adjugate inverse).
pub fn inverse_gj(m: &Mat3<f64>) -> Mat3<f64> {
    let mut a = [[0.0; 6]; 3];
    for i in 0..3 {
        a[i][..3].copy_from_slice(&m[i]);
        a[i][3 + i] = 1.0;
    }
    for c in 0..3 {
        let p = (c..3).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs())).unwrap();
        a.swap(c, p);
        let d = a[c][c];
        assert!(d.abs() > 1e-300, "singular");
        for v in a[c].iter_mut() {
            *v /= d;
        }
        for r in 0..3 {
            if r != c {
                let f = a[r][c];
                for k in 0..6 {
                    a[r][k] -= f * a[c][k];
                }
            }
        }
    }
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        out[i].copy_from_slice(&a[i][3..]);
    }
    out
}

/// `m·v`.
pub fn mv(m: &Mat3<f64>, v: &Vec3<f64>) -> Vec3<f64> {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// Largest absolute element of `a − b`.
pub fn max_diff(a: &Vec3<f64>, b: &Vec3<f64>) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
}

/// Widens an `f32` vector.
pub fn widen(v: &Vec3<f32>) -> Vec3<f64> {
    v.map(|x| x as f64)
}

/// The truth constants at `temp_c` of a model written independently of the core: each of the
/// 12 constants is the quadratic through its values at the paper's three temperatures
/// (Lagrange form), or the piecewise-linear interpolation between them.
pub fn truth_constants(temp_c: f64, quadratic: bool) -> Constants<f64> {
    let pts = read_paper_constants_csv();
    let flat = |c: &Constants<f64>| -> [f64; 12] {
        let mut a = [0.0; 12];
        for i in 0..3 {
            a[i] = c.u0_v[i];
            for j in 0..3 {
                a[3 + 3 * i + j] = c.k_v_per_g[i][j];
            }
        }
        a
    };
    let (t, v): (Vec<f64>, Vec<[f64; 12]>) = pts.iter().map(|(t, c)| (*t, flat(c))).unzip();
    let mut out = [0.0; 12];
    for k in 0..12 {
        out[k] = if quadratic {
            (0..3)
                .map(|a| {
                    let mut w = v[a][k];
                    for b in 0..3 {
                        if b != a {
                            w *= (temp_c - t[b]) / (t[a] - t[b]);
                        }
                    }
                    w
                })
                .sum()
        } else {
            // Sorted: -40, 20, 70 are rows 1, 0, 2.
            let (lo, mid, hi) = ((t[1], v[1][k]), (t[0], v[0][k]), (t[2], v[2][k]));
            let (a, b) = if temp_c <= mid.0 { (lo, mid) } else { (mid, hi) };
            a.1 + (temp_c - a.0) * (b.1 - a.1) / (b.0 - a.0)
        };
    }
    let mut c = Constants { k_v_per_g: [[0.0; 3]; 3], u0_v: [0.0; 3] };
    for i in 0..3 {
        c.u0_v[i] = out[i];
        for j in 0..3 {
            c.k_v_per_g[i][j] = out[3 + 3 * i + j];
        }
    }
    c
}
