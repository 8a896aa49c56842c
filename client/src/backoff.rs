//! Reconnection delays: exponential from `initial` by `factor`, capped at `max`, for at most
//! `max_attempts` attempts (`None` = forever).

use std::time::Duration;

/// Reconnection policy.
#[derive(Debug, Clone, PartialEq)]
pub struct Backoff {
    /// First delay.
    pub initial: Duration,
    /// Largest delay.
    pub max: Duration,
    /// Growth per attempt.
    pub factor: f64,
    /// Attempts before giving up (`None` = retry forever).
    pub max_attempts: Option<u32>,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            initial: Duration::from_millis(100),
            max: Duration::from_secs(5),
            factor: 2.0,
            max_attempts: Some(20),
        }
    }
}

impl Backoff {
    /// No retries at all (one attempt).
    pub fn none() -> Self {
        Self {
            max_attempts: Some(0),
            ..Self::default()
        }
    }

    /// The delay before retry number `attempt` (1-based), or `None` when out of attempts.
    pub fn delay(&self, attempt: u32) -> Option<Duration> {
        if self.max_attempts.is_some_and(|m| attempt > m) {
            return None;
        }
        let exp = self
            .factor
            .max(1.0)
            .powi(attempt.saturating_sub(1).min(64) as i32);
        let d = self.initial.as_secs_f64() * exp;
        Some(Duration::from_secs_f64(d.min(self.max.as_secs_f64())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grows_then_caps_then_stops() {
        let b = Backoff {
            initial: Duration::from_millis(100),
            max: Duration::from_millis(500),
            factor: 2.0,
            max_attempts: Some(5),
        };
        let d: Vec<_> = (1..=6).map(|a| b.delay(a).map(|d| d.as_millis())).collect();
        assert_eq!(
            d,
            vec![Some(100), Some(200), Some(400), Some(500), Some(500), None]
        );
        assert_eq!(Backoff::none().delay(1), None);
    }
}
