//! Code generation of C and Rust model headers (see issue "Codegen and on-target self-identification").
