//! What the identification's filter works on: a linear discrete-time model at one θ
//! (METHOD §3 (1.4.1)–(1.4.2)), the initial state's distribution and where it sits,
//! and the measurements.

/// x_{k+1} = Φ x_k + u + G w_k, w ~ N(0, Q); z_k = H x_k + v_k, v ~ N(0, R). All
/// matrices row-major; N states, L process-noise sources, m measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct Discrete {
    pub n: usize,
    pub l: usize,
    pub m: usize,
    /// Φ (N × N).
    pub phi: Vec<f64>,
    /// u (N), the deterministic input per step.
    pub u: Vec<f64>,
    /// G (N × L).
    pub g: Vec<f64>,
    /// Q (L × L).
    pub q: Vec<f64>,
    /// H (m × N).
    pub h: Vec<f64>,
    /// R (m × m).
    pub r: Vec<f64>,
}

pub use crate::model::PriorAt;

/// The initial state's distribution.
#[derive(Clone, Debug, PartialEq)]
pub struct Prior {
    /// x0 (N).
    pub x0: Vec<f64>,
    /// P0 (N × N), positive definite.
    pub p0: Vec<f64>,
    pub at: PriorAt,
}

/// The measurements z_1 … z_D: row k holds step k's m values (NaN: missing).
#[derive(Clone, Debug, PartialEq)]
pub struct Data {
    pub m: usize,
    /// t_k of each row.
    pub t: Vec<f64>,
    /// D × m, row-major.
    pub z: Vec<f64>,
}

impl Data {
    /// D, the rows.
    pub fn rows(&self) -> usize {
        self.t.len()
    }
}

/// The derivatives of a [`Discrete`] model and its [`Prior`] with respect to one
/// parameter θ_i (the same shapes; zero where an entry does not depend on θ_i).
#[derive(Clone, Debug, PartialEq)]
pub struct Partial {
    pub phi: Vec<f64>,
    pub u: Vec<f64>,
    pub g: Vec<f64>,
    pub q: Vec<f64>,
    pub h: Vec<f64>,
    pub r: Vec<f64>,
    pub x0: Vec<f64>,
    pub p0: Vec<f64>,
}

impl Partial {
    /// All zero: a parameter that nothing depends on.
    pub fn zero(model: &Discrete) -> Partial {
        let (n, l, m) = (model.n, model.l, model.m);
        Partial {
            phi: vec![0.0; n * n],
            u: vec![0.0; n],
            g: vec![0.0; n * l],
            q: vec![0.0; l * l],
            h: vec![0.0; m * n],
            r: vec![0.0; m * m],
            x0: vec![0.0; n],
            p0: vec![0.0; n * n],
        }
    }
}
