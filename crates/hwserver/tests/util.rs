//! Helpers for the hwserver integration tests.
