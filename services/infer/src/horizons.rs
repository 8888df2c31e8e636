//! The forecast horizons the service asks the model for.

use evgate_ipc::MAX_HORIZONS;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HorizonError {
    #[error(
        "--horizons-ms lists {count} horizons; a forecast carries at most {MAX_HORIZONS} \
         (evgate_ipc::MAX_HORIZONS)"
    )]
    TooMany { count: usize },
    #[error(
        "--horizons-ms value #{index} = {value} ms is outside the model's range 0 to {max} ms"
    )]
    OutOfRange { index: usize, value: f32, max: f32 },
    #[error(
        "--horizons-ms must be strictly ascending in whole microseconds (forecasts carry µs): \
         value #{index} = {value} ms follows {previous} ms"
    )]
    NotAscending {
        index: usize,
        value: f32,
        previous: f32,
    },
}

/// `requested` checked against the model's largest horizon, or, when empty, the default:
/// `MAX_HORIZONS` horizons evenly spaced up to that largest horizon (10, 20, … 100 ms when a
/// forecast carries ten).
pub fn resolve_horizons(requested: &[f32], max_horizon_ms: f32) -> Result<Vec<f32>, HorizonError> {
    if requested.is_empty() {
        return Ok((1..=MAX_HORIZONS)
            .map(|k| max_horizon_ms * k as f32 / MAX_HORIZONS as f32)
            .collect());
    }
    if requested.len() > MAX_HORIZONS {
        return Err(HorizonError::TooMany {
            count: requested.len(),
        });
    }
    for (index, &value) in requested.iter().enumerate() {
        if !(0.0..=max_horizon_ms).contains(&value) {
            return Err(HorizonError::OutOfRange {
                index,
                value,
                max: max_horizon_ms,
            });
        }
        if index > 0 && horizon_us(value) <= horizon_us(requested[index - 1]) {
            return Err(HorizonError::NotAscending {
                index,
                value,
                previous: requested[index - 1],
            });
        }
    }
    Ok(requested.to_vec())
}

/// A horizon as a forecast header carries it: whole microseconds.
pub fn horizon_us(ms: f32) -> i64 {
    (f64::from(ms) * 1000.0).round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_spans_the_model_range_evenly() {
        let horizons = resolve_horizons(&[], 100.0).unwrap();
        assert_eq!(horizons.len(), MAX_HORIZONS);
        assert_eq!(*horizons.last().unwrap(), 100.0);
        assert!((horizons[0] - 100.0 / MAX_HORIZONS as f32).abs() < 1e-6);
    }

    #[test]
    fn requested_horizons_are_checked() {
        assert_eq!(
            resolve_horizons(&[10.0, 50.0], 100.0).unwrap(),
            vec![10.0, 50.0]
        );
        assert!(matches!(
            resolve_horizons(&[10.0, 150.0], 100.0),
            Err(HorizonError::OutOfRange { index: 1, .. })
        ));
        assert!(matches!(
            resolve_horizons(&[10.0, 10.0004], 100.0),
            Err(HorizonError::NotAscending { index: 1, .. })
        ));
        assert!(matches!(
            resolve_horizons(&[50.0, 50.0], 100.0),
            Err(HorizonError::NotAscending { index: 1, .. })
        ));
        assert!(matches!(
            resolve_horizons(&[f32::NAN], 100.0),
            Err(HorizonError::OutOfRange { index: 0, .. })
        ));
        let many: Vec<f32> = (1..=MAX_HORIZONS + 1).map(|k| k as f32).collect();
        assert!(matches!(
            resolve_horizons(&many, 100.0),
            Err(HorizonError::TooMany { .. })
        ));
    }
}
