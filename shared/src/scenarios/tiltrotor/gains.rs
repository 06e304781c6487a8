//! The linear gains of NLLS-2L and NLPT-2L by pole placement. The paper
//! synthesises them by mixed H₂/H∞ with pole regions (Tables 2–3) but publishes no numbers, so
//! these are stand-ins: real closed-loop poles chosen inside each loop's Table 2 region (read
//! as: Re s < α, inside the disk of centre c and radius |r|, within the cone of
//! half-angle φ about the negative real axis; real poles satisfy every cone).
//!
//! | loop  | design model                          | poles (launch file)       | gains                                   | Table 2 region                         |
//! |-------|----------------------------------------|---------------------------|-----------------------------------------|----------------------------------------|
//! | x, y  | ë = v (e = [∫e, e, ė])                 | −1.5, −2, −2.5            | K_I, K_p, K_d = −7.5, −11.75, −6         | Re < −1, |s| < 3, cone π/36            |
//! | z     | e⁽⁴⁾ = v (e = [∫e, e, ė, ë, e⃛])        | −3, −4, −5, −6, −7        | K_I…K_ddd = −2520, −2754, −1175, −245, −25 | Re < −1.1, |s| < 80, cone π/36       |
//! | φ, θ  | e⁽⁴⁾ = v                               | −20, −24, −28, −32, −36   | −15482880, −2886144, −212800, −7760, −140 | Re < −7, |s + 7| < 110, cone π/4     |
//! | ψ     | e⁽⁴⁾ = v                               | −12, −14, −16, −18, −20   | −967680, −312384, −40000, −2540, −80     | Re < −3, |s + 3| < 20, cone π/10       |
//! | swing | [∫ḋ, ḋ]′ = [ḋ, −u], u = K_Id∫ḋ + K_pd ḋ | −1.6, −1.9                | K_Id, K_pd = 3.04, 3.5                   | Re < −1.5, |s| < 2, cone π/20          |
//!
//! Each e⁽ⁿ⁾ = v chain with v = Σ Kⱼ e⁽ʲ⁻¹⁾ (∫e first) has the characteristic polynomial
//! sⁿ⁺¹ − K_last sⁿ − … − K_I, so Kⱼ = −aⱼ of Π(s − pᵢ) = sⁿ⁺¹ + aₙsⁿ + … + a₀ (e = i − i_Ref:
//! the gains come out negative). The swing model drives ḋ with −u (the
//! aircraft's acceleration enters the pendulum with a minus sign), so its gains are
//! +aⱼ and K_pd > 0 damps; gravity's −(g/l)d is left out of the design model as the paper's
//! integrator chains do, and the unit tests check the combined x + swing loop with it.
//!
//! Speeds: the attitude poles sit at 20–36 rad/s (sτ ≤ 0.36 at τ = 0.01 s). At 8–16 rad/s the
//! attitude loop lags the outer loop enough that NLPT-2L, which has no swing term, pumps the
//! load: from γ = 0 at hover its swing grew to 1.9 rad within 20 s (measured); at 20–36 it stays
//! at its initial 0.44 rad. The ψ poles at 12–20 rad/s (inside |s + 3| < 20) keep ψ's error at
//! the noise floor: at 4–8 rad/s the roll and pitch motion of the swing damping leaks into ψ and
//! NLLS-2L's ψ RMSE was 1.4× NLPT-2L's. The attitude loop stays ≥ 8× faster than the x, y loop,
//! which assumes a unit-gain inner loop (section 3.2). The φ_Ref, θ_Ref prefilter (25 rad/s)
//! must stay slow: it also low-passes the path α → f_x^B → θ_Ref (the tilt that pitches the body
//! also pushes it, and (46) compensates that push); at 40 rad/s the vehicle is lost (measured).
//!
//! NLLS-3L (the three-loop cascade of the paper's ref. [22]) is not here: the paper gives
//! neither its structure nor its gains.

use crate::model::poly::coefficients_of_roots;

/// Π(s − pᵢ) = sᴺ + a_(N−1)s^(N−1) + … + a₀, returned as [a₀ … a_(N−1)].
fn characteristic<const N: usize>(poles: [f64; N]) -> [f64; N] {
    let c = coefficients_of_roots(&poles);
    std::array::from_fn(|k| c[k])
}

/// Gains of a chain e⁽ᴺ⁻¹⁾ = v, v = Σ Kⱼ (∫e, e, ė, …): [K_I, K_p, K_d, …] = −a.
pub fn chain_gains<const N: usize>(poles: [f64; N]) -> [f64; N] {
    characteristic(poles).map(|a| -a)
}

/// [K_Id, K_pd] of the swing loop, driven by −u.
pub fn swing_gains(poles: [f64; 2]) -> [f64; 2] {
    characteristic(poles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;

    #[test]
    fn the_notes_xy_example() {
        assert_eq!(chain_gains([-1.5, -2.0, -2.5]), [-7.5, -11.75, -6.0]);
        assert_eq!(swing_gains([-1.6, -1.9]), [1.6 * 1.9, 3.5]);
    }

    /// The table in the module doc.
    #[test]
    fn the_documented_gains() {
        assert_eq!(chain_gains([-3.0, -4.0, -5.0, -6.0, -7.0]), [-2520.0, -2754.0, -1175.0, -245.0, -25.0]);
        assert_eq!(chain_gains([-8.0, -10.0, -12.0, -14.0, -16.0]), [-215040.0, -95104.0, -16560.0, -1420.0, -60.0]);
        assert_eq!(chain_gains([-4.0, -5.0, -6.0, -7.0, -8.0]), [-6720.0, -5944.0, -2070.0, -355.0, -30.0]);
    }

    /// The x loop with the swing terms on the linearised pendulum: states (∫e_x, e_x, ė_x, d, ḋ),
    /// ẍ = v_x = K_I∫e + K_p e + K_d ė + K_Id d + K_pd ḋ, d̈ = −ẍ − (g/l)d (∫ḋ = d from a
    /// hanging start).
    #[test]
    fn the_combined_x_and_swing_loop_is_stable() {
        let [ki, kp, kd] = chain_gains([-1.5, -2.0, -2.5]);
        let [kid, kpd] = swing_gains([-1.6, -1.9]);
        let g_over_l = 9.81 / 0.5;
        let loop_with = |kid: f64, kpd: f64| {
            let row = [ki, kp, kd, kid, kpd];
            let mut a = SMatrix::<f64, 5, 5>::zeros();
            a[(0, 1)] = 1.0;
            a[(1, 2)] = 1.0;
            a[(3, 4)] = 1.0;
            for j in 0..5 {
                a[(2, j)] = row[j];
                a[(4, j)] = -row[j];
            }
            a[(4, 3)] -= g_over_l;
            a.complex_eigenvalues()
        };
        let with_swing = loop_with(kid, kpd);
        // Every mode decays; the pendulum pair is the slowest, ≈ −0.18 ± 3.39i: the Table 2 swing
        // region (|s| < 2 about a 4.4 rad/s pendulum) allows little more, ≈ −0.17 to −0.19
        // anywhere in it. The test on the full plant shows the swing damped much faster than that
        // (its load drag and the inner loop's couplings add to it).
        let slowest = with_swing.iter().map(|e| e.re).fold(f64::MIN, f64::max);
        assert!((-0.19..-0.17).contains(&slowest), "{with_swing:?}");
        let pendulum = with_swing.iter().find(|e| e.re == slowest).expect("a slowest mode");
        assert!((pendulum.im.abs() - 3.39).abs() < 0.01, "{with_swing:?}");
        // Without the swing terms (NLPT-2L) the pendulum pair sits on the imaginary axis.
        let without = loop_with(0.0, 0.0);
        let undamped = without.iter().map(|e| e.re).fold(f64::MIN, f64::max);
        assert!(undamped.abs() < 1e-9, "{without:?}");
    }
}
