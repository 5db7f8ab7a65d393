//! Which GPU architectures get native code: every one the nvcc at hand knows from Turing up, or the list
//! in `CUDA_COMPUTE_CAP` (the variable candle reads too).

/// Turing (compute capability 7.5): the oldest architecture clatch builds for, and the portable PTX's.
pub const OLDEST: u32 = 75;

/// The variable that narrows the list: `90`, `80,90`, `8.6` (as `nvidia-smi --query-gpu=compute_cap`
/// prints it) or `all`; unset or empty means all.
pub const VARIABLE: &str = "CUDA_COMPUTE_CAP";

/// The real architectures nvcc can build for (`nvcc --list-gpu-code`: `sm_75`, `sm_80`, ...), from
/// [`OLDEST`] up, ascending. Architecture-specific variants (`sm_90a`, `sm_100f`) are left out: their
/// code runs on one chip only, and nothing here needs their instructions.
pub fn supported(list_gpu_code: &str) -> Vec<u32> {
    let mut archs: Vec<u32> = list_gpu_code
        .split_whitespace()
        .filter_map(|code| code.strip_prefix("sm_")?.parse().ok())
        .filter(|&arch| arch >= OLDEST)
        .collect();
    archs.sort_unstable();
    archs.dedup();
    archs
}

/// The architectures to build native code for: all of `supported`, or those `requested` lists (each of
/// which must be one of them). `None` or an empty list means all.
pub fn select(requested: Option<&str>, supported: &[u32]) -> Result<Vec<u32>, String> {
    let requested = requested.map(str::trim).unwrap_or("");
    if requested.is_empty() || requested.eq_ignore_ascii_case("all") {
        return Ok(supported.to_vec());
    }
    let mut archs = Vec::new();
    for item in requested.split(',').map(str::trim) {
        let arch = parse(item).ok_or_else(|| {
            format!("{VARIABLE}: {item:?} is not a compute capability (write 90, 9.0 or sm_90)")
        })?;
        if !supported.contains(&arch) {
            return Err(format!(
                "{VARIABLE}: this nvcc builds for {}, not {arch}",
                names(supported)
            ));
        }
        archs.push(arch);
    }
    archs.sort_unstable();
    archs.dedup();
    Ok(archs)
}

/// `90`, `9.0`, `12.1` or `sm_90` as the number nvcc writes after `sm_` (90, 121).
fn parse(item: &str) -> Option<u32> {
    let item = item.strip_prefix("sm_").unwrap_or(item);
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    match item.split_once('.') {
        Some((major, minor)) if digits(major) && minor.len() == 1 && digits(minor) => {
            Some(major.parse::<u32>().ok()? * 10 + minor.parse::<u32>().ok()?)
        }
        None if digits(item) => item.parse().ok(),
        _ => None,
    }
}

/// `sm_75, sm_80, ...`
pub fn names(archs: &[u32]) -> String {
    archs
        .iter()
        .map(|a| format!("sm_{a}"))
        .collect::<Vec<_>>()
        .join(", ")
}
