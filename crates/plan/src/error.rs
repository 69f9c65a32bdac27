//! Errors of the plan crate.

/// What went wrong reading a profile or a plan, or planning.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A profile that is malformed or breaks an invariant.
    #[error("profile: {0}")]
    Profile(String),
    /// A plan file that is malformed or does not fit the scene.
    #[error("plan: {0}")]
    Plan(String),
    /// Settings the planner cannot honour.
    #[error("{0}")]
    Settings(String),
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, PlanError>;
