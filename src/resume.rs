//! A long computation's state, kept so that a run interrupted there (a server restart)
//! goes on from that point instead of from the start, and ends with the result an
//! uninterrupted run gives, bit for bit: an analysis's between two steps
//! ([`LoopState`]), a Monte Carlo's between two chunks of steps ([`MonteCarloState`]).
//!
//! A state is text (a [`crate::exec::Memo`] value: the core has no storage): JSON in
//! which every f64 is its bit pattern (a u64), so that NaN, ±∞ and −0 read back as
//! they were. It is what the loop carries from one step to the next; what a step
//! recomputes from the model and k (the inputs at t_k, the factorisation of Rv, the
//! stationary solution, the Monte Carlo's gains) is not in it. A state of another
//! format, another model size or another run is not taken: the run starts over.

//!
//! This module holds what every kind's state shares: f64s kept as their bits ([`F`],
//! and the serde `with` modules [`f64_bits`], [`f64s`] and [`columns`] for the loops'
//! own structs, which are their states; [`same_shape`], whether a kept state has the
//! sizes of a fresh one). The states are their kinds':
//! `analysis::state`, `monte_carlo::state`.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// An f64 as its bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct F(pub f64);

impl Serialize for F {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(self.0.to_bits())
    }
}

impl<'de> Deserialize<'de> for F {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<F, D::Error> {
        u64::deserialize(d).map(|b| F(f64::from_bits(b)))
    }
}

/// Values as their bits.
pub(crate) fn bits(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F(x)).collect()
}

/// `dst` set to the values of `src`'s bits (of its length).
pub(crate) fn put(dst: &mut [f64], src: &[F]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = s.0;
    }
}

/// Bits as values.
pub(crate) fn values(v: &[F]) -> Vec<f64> {
    v.iter().map(|x| x.0).collect()
}

/// serde `with`: an f64 as its bits.
pub(crate) mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}

/// serde `with`: f64s as their bits.
pub(crate) mod f64s {
    use serde::{Deserialize, Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| x.to_bits()))
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let b = Vec::<u64>::deserialize(d)?;
        Ok(b.into_iter().map(f64::from_bits).collect())
    }
}

/// serde `with`: columns of optional f64s as their bits.
pub(crate) mod columns {
    use super::F;
    use serde::{Deserialize, Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(
        v: &[Vec<Option<f64>>],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(
            v.iter()
                .map(|c| c.iter().map(|x| x.map(F)).collect::<Vec<_>>()),
        )
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Vec<Vec<Option<f64>>>, D::Error> {
        let b = Vec::<Vec<Option<F>>>::deserialize(d)?;
        Ok(b.into_iter()
            .map(|c| c.into_iter().map(|x| x.map(|f| f.0)).collect())
            .collect())
    }
}

/// Whether a kept state `got` (as JSON) has the shape of `fresh`, a state made for
/// the run at hand: the same members, and arrays of the same lengths, recursively. A
/// member null in either (an `Option` not set) is not compared.
pub fn same_shape(got: &serde_json::Value, fresh: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (got, fresh) {
        (Value::Null, _) | (_, Value::Null) => true,
        (Value::Array(a), Value::Array(b)) => {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| same_shape(x, y))
        }
        (Value::Object(a), Value::Object(b)) => {
            a.len() == b.len()
                && b.iter()
                    .all(|(k, v)| a.get(k).is_some_and(|g| same_shape(g, v)))
        }
        (a, b) => std::mem::discriminant(a) == std::mem::discriminant(b),
    }
}

#[cfg(test)]
mod tests {
    use super::same_shape;
    use serde_json::json;

    #[test]
    fn a_shorter_vector_or_a_missing_member_is_another_shape() {
        let fresh = json!({"y": [0, 0], "joseph": {"r": [0, 0, 0, 0]}, "frozen_at": null});
        let kept = json!({"y": [7, 8], "joseph": {"r": [1, 2, 3, 4]}, "frozen_at": 12});
        assert!(same_shape(&kept, &fresh));
        let short = json!({"y": [7], "joseph": {"r": [1, 2, 3, 4]}, "frozen_at": 12});
        assert!(!same_shape(&short, &fresh));
        let inner = json!({"y": [7, 8], "joseph": {"r": [1, 2, 3]}, "frozen_at": null});
        assert!(!same_shape(&inner, &fresh));
        let missing = json!({"y": [7, 8], "frozen_at": null});
        assert!(!same_shape(&missing, &fresh));
    }
}
