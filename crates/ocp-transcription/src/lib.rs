//! Optimal control problems over ODE models (paper eqs. 33–34): multiple shooting,
//! integrators with sensitivities, SQP and QPs solved with Clarabel (issue 5).
