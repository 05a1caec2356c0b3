//! Integration tests of the starter library.
