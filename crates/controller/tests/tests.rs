//! Integration tests of the controller library.
