//! Helpers shared by the end-to-end tests (building QEMU images, running them, decoding output).
