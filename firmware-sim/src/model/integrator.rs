//! A fixed-step classical Runge–Kutta integrator, kept apart from every model (the plant's
//! derivative is a pure function; this module only knows how to advance a state along one).
//!
//! The state type says how to take a step along a derivative ([`OdeState::advanced`]); nothing
//! here allocates, so the twin's 1 kHz physics step stays allocation-free.

/// A state that can be advanced along its derivative: `x + h·ẋ`.
pub trait OdeState: Copy {
    /// The time derivative of the state.
    type Derivative: Copy;

    /// Returns `self + h · d`.
    #[must_use]
    fn advanced(&self, d: &Self::Derivative, h: f64) -> Self;

    /// The RK4 update `self + h/6 (k1 + 2 k2 + 2 k3 + k4)`. By default the four terms are
    /// applied one by one, so that the state type needs no sums; a state whose derivative can
    /// be summed may form the weighted sum first (fewer operations, equal up to rounding).
    #[must_use]
    fn rk4_update(&self, k: [&Self::Derivative; 4], h: f64) -> Self {
        self.advanced(k[0], h / 6.0)
            .advanced(k[1], h / 3.0)
            .advanced(k[2], h / 3.0)
            .advanced(k[3], h / 6.0)
    }
}

impl OdeState for f64 {
    type Derivative = f64;
    fn advanced(&self, d: &f64, h: f64) -> f64 {
        self + h * d
    }
}

/// One classical RK4 step of size `h_s` for the autonomous system ẋ = f(x) (inputs are held
/// constant over the step, i.e. a zero-order hold, as the firmware's outputs are).
#[must_use]
pub fn rk4_step<S, F>(x: &S, h_s: f64, mut f: F) -> S
where
    S: OdeState,
    F: FnMut(&S) -> S::Derivative,
{
    let k1 = f(x);
    let k2 = f(&x.advanced(&k1, 0.5 * h_s));
    let k3 = f(&x.advanced(&k2, 0.5 * h_s));
    let k4 = f(&x.advanced(&k3, h_s));
    x.rk4_update([&k1, &k2, &k3, &k4], h_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponential_decay_matches_closed_form() {
        // x' = −x, x(0) = 1 → x(1) = e^-1. RK4's global error is O(h^4).
        let h = 0.01;
        let mut x = 1.0_f64;
        for _ in 0..100 {
            x = rk4_step(&x, h, |x| -x);
        }
        let err = (x - (-1.0_f64).exp()).abs();
        assert!(err < 1e-9, "error {err}");
    }

    #[test]
    fn fourth_order_convergence() {
        // Halving h must shrink the error by about 2^4.
        let run = |h: f64, n: usize| {
            let mut x = 1.0_f64;
            for _ in 0..n {
                x = rk4_step(&x, h, |x| -x);
            }
            (x - (-1.0_f64).exp()).abs()
        };
        let ratio = run(0.1, 10) / run(0.05, 20);
        assert!((ratio - 16.0).abs() < 1.0, "ratio {ratio}");
    }
}
