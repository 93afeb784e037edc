//! First-order deposition dynamics, paper 003 eq. 34: G(s) = 1/(τs + 1), with the
//! paper's identified τ = 0.0873 s (Sec. 3.2).
//!
//! Discretised exactly for a zero-order-hold input: over one period `dt` the output
//! moves the fraction `1 − exp(−dt/τ)` of the way to the input. This is the same
//! filter for the virtual printer's flow and for the filtered B-spline basis (eq. 38),
//! so a compensation computed through it is exact for a printer that obeys it.

/// Filters `input` (sampled every `dt_s`) through G(s) = 1/(τs+1), starting from
/// `initial` (the output before the first sample).
pub fn first_order_lag(input: &[f64], dt_s: f64, tau_s: f64, initial: f64) -> Vec<f64> {
    let mut output = vec![0.0; input.len()];
    first_order_lag_into(input, dt_s, tau_s, initial, &mut output);
    output
}

/// In-place form of [`first_order_lag`]: writes into `output` (same length as `input`).
/// Sample k of the output is the state after input sample k has been held for `dt_s`.
pub fn first_order_lag_into(input: &[f64], dt_s: f64, tau_s: f64, initial: f64, output: &mut [f64]) {
    assert_eq!(input.len(), output.len(), "first_order_lag_into: input and output lengths differ");
    let step = if tau_s > 0.0 { 1.0 - (-dt_s / tau_s).exp() } else { 1.0 };
    let mut state = initial;
    for (out, &u) in output.iter_mut().zip(input) {
        state += step * (u - state);
        *out = state;
    }
}

/// What the lag adds to `input` when it starts from rest: G(s)·u − u at every sample.
/// For a deposition-velocity command this is the flow excess of eq. 34 (positive while
/// the head slows, negative while it speeds up), which a compensation must cancel.
pub fn lag_excess(input: &[f64], dt_s: f64, tau_s: f64) -> Vec<f64> {
    let mut excess = first_order_lag(input, dt_s, tau_s, 0.0);
    excess.iter_mut().zip(input).for_each(|(lagged, u)| *lagged -= u);
    excess
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lag_excess_of_a_step_is_the_decaying_shortfall() {
        // A unit step from rest: G·u − u = −exp(−t/τ) at t = (k+1)·dt.
        let (dt, tau) = (0.001, 0.0873);
        for (k, e) in lag_excess(&[1.0; 300], dt, tau).iter().enumerate() {
            assert!((e + (-((k + 1) as f64) * dt / tau).exp()).abs() < 1e-12, "sample {k}");
        }
    }

    #[test]
    fn step_response_matches_the_closed_form() {
        // For a unit step the exact response is 1 − exp(−t/τ) at every sample t = (k+1)·dt.
        let (dt, tau) = (0.001, 0.0873);
        let out = first_order_lag(&[1.0; 500], dt, tau, 0.0);
        for (k, y) in out.iter().enumerate() {
            let t = (k + 1) as f64 * dt;
            assert!((y - (1.0 - (-t / tau).exp())).abs() < 1e-12, "sample {k}");
        }
    }

    #[test]
    fn zero_time_constant_passes_the_input_through() {
        let input = [0.0, 1.0, 3.0, -2.0];
        assert_eq!(first_order_lag(&input, 0.01, 0.0, 5.0), input.to_vec());
    }

    #[test]
    fn lag_conserves_the_integral_once_settled() {
        // A pulse's area passes through a unity-gain filter unchanged (G(0) = 1).
        let dt = 0.001;
        let mut input = vec![0.0; 3000];
        input[100..400].iter_mut().for_each(|u| *u = 2.0);
        let out = first_order_lag(&input, dt, 0.0873, 0.0);
        let area_in: f64 = input.iter().sum::<f64>() * dt;
        let area_out: f64 = out.iter().sum::<f64>() * dt;
        assert!((area_in - area_out).abs() < 1e-9 * area_in.max(1.0) + 1e-9);
    }
}
