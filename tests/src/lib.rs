//! Shared helpers for the host tests (register-level chip models live here).
