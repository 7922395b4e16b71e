//! The measurement section's blind measurements: a row of C that is 0, refused when
//! the measurement has no noise either (its innovation variance q is 0), else a note.

use super::{Errors, MeasurementNoise};

/// A measurement whose row of C is 0 measures no state. With no noise either (every
/// source of its row of Γ has a constant 0 entry or a variance of 0; in the seed's
/// form Γ = C g the row is 0 with C's) its innovation variance q_jj is 0 at every step
/// and the filter fails at its first: refused here, naming the row. With noise it is
/// noise only, which the filter weighs at 0: a note.
pub(super) fn blind_measurements(
    c: &[f64],
    noise: &MeasurementNoise,
    v: &[f64],
    names: &[String],
    n: usize,
    errs: &mut Errors,
    notes: &mut Vec<String>,
) {
    let ms = noise.sources();
    for (j, name) in names.iter().enumerate() {
        if c.len() < (j + 1) * n || c[j * n..(j + 1) * n].iter().any(|&x| x != 0.0) {
            continue;
        }
        let silent = match noise {
            MeasurementNoise::SeedG(_) => true,
            MeasurementNoise::Gamma(g) => (0..ms).all(|l| {
                let i = j * ms + l;
                v.get(l * ms + l) == Some(&0.0) || (!g.varies(i) && g.values.get(i) == Some(&0.0))
            }),
        };
        let path = format!("measurement.c[{j}]");
        if silent {
            let form = match noise {
                MeasurementNoise::SeedG(_) => {
                    "and so is its noise (the seed's form Z = c (y + gΦ) scales the noise by c too)"
                }
                MeasurementNoise::Gamma(_) => {
                    "and it has no noise (its row of gamma is 0, or its sources' variances are)"
                }
            };
            errs.at(
                &path,
                format!("measurement \"{name}\" measures nothing: its row of c is 0, {form}, so its innovation variance q = C r Cᵀ + Γ V Γᵀ is 0 and the filter cannot use it; give the row a non-zero entry, or leave the measurement out"),
            );
        } else {
            notes.push(format!(
                "{path}: measurement \"{name}\" measures no state (its row of c is 0): it is noise only, and the filter gives it no weight"
            ));
        }
    }
}
