//! Affine matrix expressions in scalar decision variables, and LMI programs
//! (F(x) = F₀ + Σ xₖFₖ ⪰ 0) solved by clarabel's semidefinite cone.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::DMatrix;

/// F₀ + Σ xₖFₖ: `coef[k]` is Fₖ (dense: the programs here have a few dozen variables).
#[derive(Clone, Debug)]
pub struct Aff {
    pub constant: DMatrix<f64>,
    pub coef: Vec<DMatrix<f64>>,
}

impl Aff {
    pub fn constant(m: DMatrix<f64>, vars: usize) -> Aff {
        let (r, c) = m.shape();
        Aff { constant: m, coef: vec![DMatrix::zeros(r, c); vars] }
    }

    pub fn zeros(r: usize, c: usize, vars: usize) -> Aff {
        Aff::constant(DMatrix::zeros(r, c), vars)
    }

    pub fn shape(&self) -> (usize, usize) {
        self.constant.shape()
    }

    fn map(&self, f: impl Fn(&DMatrix<f64>) -> DMatrix<f64>) -> Aff {
        Aff { constant: f(&self.constant), coef: self.coef.iter().map(&f).collect() }
    }

    /// m · self.
    pub fn left(&self, m: &DMatrix<f64>) -> Aff {
        self.map(|x| m * x)
    }

    pub fn t(&self) -> Aff {
        self.map(|x| x.transpose())
    }

    pub fn scale(&self, s: f64) -> Aff {
        self.map(|x| x * s)
    }

    pub fn add(&self, o: &Aff) -> Aff {
        Aff {
            constant: &self.constant + &o.constant,
            coef: self.coef.iter().zip(&o.coef).map(|(a, b)| a + b).collect(),
        }
    }

    pub fn sub(&self, o: &Aff) -> Aff {
        self.add(&o.scale(-1.0))
    }

    /// The block matrix of `rows` (every block of a row the same height).
    pub fn block(rows: &[Vec<Aff>]) -> Aff {
        let heights: Vec<usize> = rows.iter().map(|r| r[0].shape().0).collect();
        let widths: Vec<usize> = rows[0].iter().map(|b| b.shape().1).collect();
        let (h, w) = (heights.iter().sum(), widths.iter().sum());
        let vars = rows[0][0].coef.len();
        let mut out = Aff::zeros(h, w, vars);
        let mut r0 = 0;
        for (row, height) in rows.iter().zip(&heights) {
            let mut c0 = 0;
            for (b, width) in row.iter().zip(&widths) {
                assert_eq!(b.shape(), (*height, *width), "block shapes");
                out.constant.view_mut((r0, c0), (*height, *width)).copy_from(&b.constant);
                for (o, c) in out.coef.iter_mut().zip(&b.coef) {
                    o.view_mut((r0, c0), (*height, *width)).copy_from(c);
                }
                c0 += width;
            }
            r0 += height;
        }
        out
    }

    /// The value at x.
    pub fn at(&self, x: &[f64]) -> DMatrix<f64> {
        self.coef.iter().zip(x).fold(self.constant.clone(), |acc, (c, v)| acc + c * *v)
    }
}

/// Decision variables, allocated in order.
#[derive(Default)]
pub struct Vars {
    pub count: usize,
}

/// A symmetric n×n or a full r×c matrix of fresh variables, or a scalar; built once `count` is
/// final (two passes: allocate, then build with `total`).
#[derive(Clone, Copy, Debug)]
pub enum VarMatrix {
    Sym { n: usize, at: usize },
    Full { r: usize, c: usize, at: usize },
}

impl Vars {
    pub fn sym(&mut self, n: usize) -> VarMatrix {
        let at = self.count;
        self.count += n * (n + 1) / 2;
        VarMatrix::Sym { n, at }
    }

    pub fn full(&mut self, r: usize, c: usize) -> VarMatrix {
        let at = self.count;
        self.count += r * c;
        VarMatrix::Full { r, c, at }
    }
}

impl VarMatrix {
    pub fn expr(&self, vars: usize) -> Aff {
        match *self {
            VarMatrix::Sym { n, at } => {
                let mut a = Aff::zeros(n, n, vars);
                let mut k = at;
                for j in 0..n {
                    for i in 0..=j {
                        a.coef[k][(i, j)] = 1.0;
                        a.coef[k][(j, i)] = 1.0;
                        k += 1;
                    }
                }
                a
            }
            VarMatrix::Full { r, c, at } => {
                let mut a = Aff::zeros(r, c, vars);
                for i in 0..r {
                    for j in 0..c {
                        a.coef[at + i * c + j][(i, j)] = 1.0;
                    }
                }
                a
            }
        }
    }

    pub fn value(&self, x: &[f64]) -> DMatrix<f64> {
        self.expr(x.len()).at(x)
    }
}

/// The upper triangle by columns, off-diagonals × √2 (clarabel's PSD triangle).
fn svec(m: &DMatrix<f64>) -> Vec<f64> {
    let n = m.nrows();
    let mut v = Vec::with_capacity(n * (n + 1) / 2);
    for j in 0..n {
        for i in 0..=j {
            let s = if i == j { 1.0 } else { std::f64::consts::SQRT_2 };
            v.push(s * 0.5 * (m[(i, j)] + m[(j, i)]));
        }
    }
    v
}

/// min cᵀx subject to every `psd` expression ⪰ 0. Returns x, or the solver's status.
pub fn minimise(c: &[f64], psd: &[Aff]) -> Result<Vec<f64>, String> {
    let vars = c.len();
    let mut rows: Vec<(usize, usize, f64)> = Vec::new();
    let mut b = Vec::new();
    let mut cones = Vec::new();
    for f in psd {
        let start = b.len();
        b.extend(svec(&f.constant));
        for (k, fk) in f.coef.iter().enumerate() {
            for (i, v) in svec(fk).into_iter().enumerate() {
                if v != 0.0 {
                    rows.push((start + i, k, -v));
                }
            }
        }
        cones.push(SupportedConeT::PSDTriangleConeT(f.shape().0));
    }
    let m = b.len();
    let (mut ri, mut ci, mut vi) = (vec![], vec![], vec![]);
    for (r, col, v) in rows {
        ri.push(r);
        ci.push(col);
        vi.push(v);
    }
    let a = CscMatrix::new_from_triplets(m, vars, ri, ci, vi);
    let p = CscMatrix::zeros((vars, vars));
    let settings = DefaultSettings {
        verbose: std::env::var_os("LMI_VERBOSE").is_some(),
        max_iter: 500,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p, c, &a, &b, &cones, settings).map_err(|e| format!("{e:?}"))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(solver.solution.x.clone()),
        s => Err(format!("{s:?}")),
    }
}
