//! Scoring a technique's hits against the exact ones, in texels of the
//! height map: the error a viewer sees as a displaced feature drawn in the
//! wrong place, independent of the map's physical size.

use super::Row;
use glam::Vec2;

/// Hit error in texels of a `height`-sized map: `None` when one of `want`
/// (the exact hit) and `got` hits and the other misses, `Some(None)` when
/// both miss (agreeing, but no error to measure), else the distance
/// between the two texture coordinates.
pub fn texel_error(
    height: [usize; 2],
    want: Option<Vec2>,
    got: Option<Vec2>,
) -> Option<Option<f32>> {
    match (want, got) {
        (Some(w), Some(g)) => Some(Some(
            ((g - w) * Vec2::new(height[0] as f32, height[1] as f32)).length(),
        )),
        (None, None) => Some(None),
        _ => None,
    }
}

/// The error of a set of hits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Score {
    /// Fraction of rays whose hit or miss is wrong.
    pub wrong: f64,
    /// Mean error of the rays both hit, texels (0 when there are none).
    pub mean: f64,
    /// 99th percentile of that error, texels (0 when there are none).
    pub p99: f64,
}

/// Scores `got` against `exact`, ray by ray ([`texel_error`]), on a map of
/// `size` texels.
pub fn score(size: [usize; 2], exact: &[Option<Vec2>], got: &[Option<Vec2>]) -> Score {
    let mut wrong = 0usize;
    let mut errors = Vec::new();
    for (w, g) in exact.iter().zip(got) {
        match texel_error(size, *w, *g) {
            None => wrong += 1,
            Some(Some(e)) => errors.push(e as f64),
            Some(None) => {}
        }
    }
    errors.sort_by(f64::total_cmp);
    let mean = if errors.is_empty() {
        0.0
    } else {
        errors.iter().sum::<f64>() / errors.len() as f64
    };
    let p99 = if errors.is_empty() {
        0.0
    } else {
        errors[((errors.len() as f64 * 0.99) as usize).min(errors.len() - 1)]
    };
    Score {
        wrong: wrong as f64 / exact.len() as f64,
        mean,
        p99,
    }
}

/// Error bound of the equal-error table: a 99th percentile below half a
/// texel (a feature drawn within its own texel), with at most 1% of rays
/// getting hit/miss wrong.
pub const EQUAL_ERROR_TEXELS: f64 = 0.5;

/// For every map, elevation and technique (the first row of each group),
/// the cheapest row (fewest fetches) within [`EQUAL_ERROR_TEXELS`], if any:
/// what each technique costs at equal image quality.
pub fn equal_error(rows: &[Row]) -> Vec<(&Row, Option<&Row>)> {
    let mut out: Vec<(&Row, Option<&Row>)> = Vec::new();
    for r in rows {
        let ok = r.p99_error < EQUAL_ERROR_TEXELS && r.wrong <= 0.01;
        let same =
            |o: &Row| o.map == r.map && o.elevation == r.elevation && o.technique == r.technique;
        match out.iter_mut().find(|(g, _)| same(g)) {
            Some((_, best)) => {
                if ok && best.is_none_or(|b| r.fetches < b.fetches) {
                    *best = Some(r);
                }
            }
            None => out.push((r, ok.then_some(r))),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_core::techniques::Technique;

    #[test]
    fn errors_are_in_texels_and_disagreeing_misses_are_wrong() {
        let at = |u, v| Some(Vec2::new(u, v));
        let e = texel_error([10, 20], at(0.5, 0.5), at(0.6, 0.55))
            .unwrap()
            .unwrap();
        assert!((e - 2.0f32.sqrt()).abs() < 1e-5, "{e}");
        assert_eq!(texel_error([10, 20], None, None), Some(None));
        assert_eq!(texel_error([10, 20], at(0.5, 0.5), None), None);
        assert_eq!(texel_error([10, 20], None, at(0.5, 0.5)), None);
    }

    #[test]
    fn the_score_counts_wrong_rays_and_ranks_the_errors() {
        // 100 rays: 98 both hit, errors 0..97 hundredths of the map's one
        // texel; one hit/miss disagreement; one agreeing miss.
        let exact: Vec<_> = (0..100).map(|k| (k != 99).then_some(Vec2::ZERO)).collect();
        let got: Vec<_> = (0..100)
            .map(|k| (k < 98).then(|| Vec2::new(k as f32 / 100.0, 0.0)))
            .collect();
        let s = score([1, 1], &exact, &got);
        assert_eq!(s.wrong, 0.01);
        assert!((s.mean - 0.485).abs() < 1e-6, "{s:?}");
        // The 99th percentile of 98 errors is the largest (index 97).
        assert!((s.p99 - 0.97).abs() < 1e-6, "{s:?}");
        let none = score([1, 1], &[None], &[None]);
        assert_eq!((none.wrong, none.mean, none.p99), (0.0, 0.0, 0.0));
    }

    fn row(technique: Technique, budget: u32, p99_error: f64, fetches: f64) -> Row {
        Row {
            map: "m".into(),
            elevation: 10.0,
            technique,
            budget,
            rays: 1,
            wrong: 0.0,
            mean_error: 0.0,
            p99_error,
            fetches,
            ns_per_ray: 1.0,
            gpu_ns_per_ray: None,
        }
    }

    #[test]
    fn equal_error_picks_the_cheapest_row_within_the_bound() {
        let rows = [
            row(Technique::Pom, 4, 2.0, 4.0),
            row(Technique::Pom, 8, 0.4, 8.0),
            row(Technique::Pom, 16, 0.1, 16.0),
            row(Technique::Steep, 4, 3.0, 4.0),
        ];
        let e = equal_error(&rows);
        assert_eq!(e.len(), 2);
        assert_eq!((e[0].0.budget, e[0].1.map(|r| r.budget)), (4, Some(8)));
        assert_eq!((e[1].0.technique, e[1].1), (Technique::Steep, None));
    }
}
