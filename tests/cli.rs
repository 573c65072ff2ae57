//! End-to-end tests of the `rgm` command.
