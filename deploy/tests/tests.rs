//! Integration tests of the `alfd` binary, in one test binary.

mod sweep;
