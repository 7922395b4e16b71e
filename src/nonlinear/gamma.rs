//! The procedure's weights (METHOD §4, seed (16)): from the regularisation steps
//! α_0 … α_{K−1},
//!
//! ```text
//!     γ_i^k = α_{i−1} (1 − α_i²)(1 − α_{i+1}²) ··· (1 − α_{k−1}²),   i = 1…k
//! ```
//!
//! (the empty product is 1: γ_k^k = α_{k−1}); filter k's measurement noise is
//! R_k = V/γ_k^k and its earlier filters' residuals enter with w_i^k = γ_i^k/γ_k^k.

/// The table γ: row k−1 holds γ_1^k … γ_k^k (k entries).
pub fn gamma(alpha: &[f64]) -> Vec<Vec<f64>> {
    (1..=alpha.len())
        .map(|k| {
            (1..=k)
                .map(|i| {
                    alpha[i..k]
                        .iter()
                        .fold(alpha[i - 1], |g, a| g * (1.0 - a * a))
                })
                .collect()
        })
        .collect()
}

/// The residual weights w_i^k = γ_i^k / γ_k^k, in `gamma`'s shape (w_k^k = 1).
pub fn weights(gamma: &[Vec<f64>]) -> Vec<Vec<f64>> {
    gamma
        .iter()
        .map(|row| {
            let own = row[row.len() - 1];
            row.iter().map(|g| g / own).collect()
        })
        .collect()
}

/// Why `alpha` cannot be a schedule (at `path`), if it cannot: each α_j finite,
/// 0 < α_0 ≤ 1 and 0 < α_j < 1 for j ≥ 1 (else the weights change sign or vanish).
pub fn check(alpha: &[f64], max: usize) -> Result<(), (String, String)> {
    if alpha.is_empty() || alpha.len() > max {
        return Err((
            String::new(),
            format!(
                "expected 1 to {max} regularisation steps α_0…α_(K−1), got {}",
                alpha.len()
            ),
        ));
    }
    for (j, &a) in alpha.iter().enumerate() {
        let ok = if j == 0 {
            a > 0.0 && a <= 1.0
        } else {
            a > 0.0 && a < 1.0
        };
        if !ok {
            let range = if j == 0 {
                "0 < α_0 ≤ 1"
            } else {
                "0 < α_j < 1 for j ≥ 1"
            };
            return Err((
                format!("[{j}]"),
                format!(
                    "expected {range} (else the weights γ change sign or vanish), got {}",
                    crate::text::num(a)
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// METHOD §4's products by hand for α = (1, 0.8, 0.6).
    #[test]
    fn the_table_by_hand() {
        let g = gamma(&[1.0, 0.8, 0.6]);
        assert_eq!(g[0], vec![1.0]);
        let (a1, a2) = (0.8f64, 0.6f64);
        assert_eq!(g[1], vec![1.0 - a1 * a1, a1]);
        assert_eq!(
            g[2],
            vec![(1.0 - a1 * a1) * (1.0 - a2 * a2), a1 * (1.0 - a2 * a2), a2]
        );
        let w = weights(&g);
        assert_eq!(w[1], vec![(1.0 - a1 * a1) / a1, 1.0]);
    }

    #[test]
    fn schedules_out_of_range_are_refused() {
        assert!(check(&[1.0, 0.5], 16).is_ok());
        assert_eq!(check(&[1.0, 1.0], 16).unwrap_err().0, "[1]");
        assert_eq!(check(&[0.0], 16).unwrap_err().0, "[0]");
        assert!(check(&[], 16).is_err());
    }
}
