//! PIPELINE.toml parsing and validation (no logs are read).
#![no_main]
use ferrosid::pipeline::LoadedConfig;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = LoadedConfig::from_text(std::path::Path::new("fuzz/pipeline.toml"), text);
    }
});
