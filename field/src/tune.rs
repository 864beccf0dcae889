//! Closed-form tuning of the seed 000 evaporation (MODELS.md M1, eqs. 23 and 26).

/// Why a tuning question has no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TuneError {
    /// An input is not finite, or outside the range where the closed form has a solution (a
    /// non-positive time or rate, or levels in the wrong order relative to each other and to the
    /// ambient level).
    #[error("{name} = {value}: {reason}")]
    Impossible {
        /// The input at fault, as the tools name it (`p0`, `ptm`, `tm`, `k`, `level`, `pa`).
        name: &'static str,
        /// Its value.
        value: f64,
        /// The condition it breaks.
        reason: String,
    },
}

fn impossible(name: &'static str, value: f64, reason: impl Into<String>) -> TuneError {
    TuneError::Impossible {
        name,
        value,
        reason: reason.into(),
    }
}

fn finite(name: &'static str, v: f64) -> Result<(), TuneError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(impossible(name, v, "must be a finite number"))
    }
}

/// Seed 000 eq. 23: the evaporation rate K (1/s) that takes P0 to P_tm in t_m seconds with
/// ambient pheromone Pa: K = −(1/t_m)·ln((P_tm − Pa)/(P0 − Pa)).
pub fn k_per_s(p0: f64, p_tm: f64, t_m_s: f64, pa: f64) -> Result<f64, TuneError> {
    for (n, v) in [("p0", p0), ("ptm", p_tm), ("tm", t_m_s), ("pa", pa)] {
        finite(n, v)?;
    }
    if t_m_s <= 0.0 {
        return Err(impossible("tm", t_m_s, "the time must be > 0 s"));
    }
    if p0 <= pa {
        return Err(impossible(
            "p0",
            p0,
            format!("must be above the ambient level pa = {pa}"),
        ));
    }
    if p_tm >= p0 {
        return Err(impossible(
            "ptm",
            p_tm,
            format!("must be below p0 = {p0}: evaporation only lowers a cell"),
        ));
    }
    if p_tm <= pa {
        return Err(impossible(
            "ptm",
            p_tm,
            format!("must be above the ambient level pa = {pa}: the decay approaches pa but never reaches it"),
        ));
    }
    Ok(-((p_tm - pa) / (p0 - pa)).ln() / t_m_s)
}

/// Seed 000 eq. 26: the time (s) for P0 to fall to the level T with rate K and ambient Pa:
/// t = −(1/K)·ln((T − Pa)/(P0 − Pa)).
pub fn time_to_threshold_s(p0: f64, k_per_s: f64, level: f64, pa: f64) -> Result<f64, TuneError> {
    for (n, v) in [("p0", p0), ("k", k_per_s), ("level", level), ("pa", pa)] {
        finite(n, v)?;
    }
    if k_per_s <= 0.0 {
        return Err(impossible(
            "k",
            k_per_s,
            "the evaporation rate must be > 0 per second",
        ));
    }
    if p0 <= pa {
        return Err(impossible(
            "p0",
            p0,
            format!("must be above the ambient level pa = {pa}"),
        ));
    }
    if level <= pa {
        return Err(impossible(
            "level",
            level,
            format!("must be above the ambient level pa = {pa}: the decay never reaches it"),
        ));
    }
    if level > p0 {
        return Err(impossible(
            "level",
            level,
            format!("must not exceed p0 = {p0}"),
        ));
    }
    Ok(-((level - pa) / (p0 - pa)).ln() / k_per_s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn papers_check_35_to_18_in_about_116_s() {
        let t = time_to_threshold_s(35.0, 0.0057, 18.0, 0.0).unwrap();
        assert!((t - 116.0).abs() < 1.0, "t = {t}");
    }

    #[test]
    fn k_and_threshold_are_inverse() {
        let k = k_per_s(50.0, 20.0, 90.0, 5.0).unwrap();
        assert_relative_eq!(
            time_to_threshold_s(50.0, k, 20.0, 5.0).unwrap(),
            90.0,
            epsilon = 1e-9
        );
    }

    #[test]
    fn impossible_inputs_say_why() {
        let e = k_per_s(35.0, 40.0, 10.0, 0.0).unwrap_err().to_string();
        assert!(e.contains("ptm") && e.contains("40"), "{e}");
        let e = time_to_threshold_s(35.0, 0.0057, 2.0, 5.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("level") && e.contains("ambient"), "{e}");
        assert!(time_to_threshold_s(35.0, 0.0, 18.0, 0.0).is_err());
    }
}
