// Generalized-α's step coefficients (coopdyn/integrators/implicit.py: alpha_coefficients, and
// GeneralizedAlpha.step): for the unknown x̂ = (1 − α_m)a⁺ + α_m a, q⁺ = q ⊕ (h v + dq_a·a +
// βhc x̂) and v⁺ = v + dv_a·a + γc x̂ with c = h/(1 − α_m); the step matrix M + γ' D̃ + β' K̃ has
// γ' = (1 − α_f)γc and β' = (1 − α_f)βhc. Shared by the compiled method and its sensitivity twin.
#pragma once

namespace coopdyn_native {

struct AlphaCoefficients {
  double c, dq_a, dv_a, gp, bp;
};

inline AlphaCoefficients alpha_coefficients(double am, double af, double g, double b, double h) {
  const double c = h / (1.0 - am);
  return {c, h * h * (0.5 - b - b * am / (1.0 - am)), h * (1.0 - g - g * am / (1.0 - am)), (1.0 - af) * g * c,
          (1.0 - af) * b * h * c};
}

}  // namespace coopdyn_native
