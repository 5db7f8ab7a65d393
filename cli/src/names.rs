//! Flags that take the library's names: the option enums ([`clatch::NamedOption`]: `--subpixel`,
//! `--ranking`, `--level-budget`, `--smoothing`) and `--backend`. The names, their help and their
//! parsing are the library's; this file only hands them to clap.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clatch::{Backend, NamedOption};

/// The value parser of a flag taking an option enum `T`: `T`'s names as clap's possible values (with
/// their summaries in `--help`; a wrong name refused with the list and the closest name), read by
/// `T`'s `FromStr`.
pub fn named<T: NamedOption>() -> impl TypedValueParser<Value = T> {
    let values = T::VALUES
        .iter()
        .map(|v| PossibleValue::new(v.name()).help(v.summary()));
    PossibleValuesParser::new(values).try_map(|name| name.parse::<T>())
}

/// What `--backend` asks for: `auto`, kept as asked until the command runs (when [`Backend::auto`]
/// probes the device), or a backend named by the library (`cpu`; `cuda`, on the device of
/// `--device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BackendFlag {
    /// `None` for `auto`.
    named: Option<Backend>,
}

impl BackendFlag {
    /// `--backend auto`.
    pub const AUTO: Self = Self { named: None };

    /// `--backend` naming `backend`.
    pub fn named(backend: Backend) -> Self {
        Self {
            named: Some(backend),
        }
    }

    /// The backend asked for, a CUDA one on device `device` (`auto`: CUDA device 0 when usable, else
    /// the CPU).
    pub fn backend(self, device: usize) -> Backend {
        match self.named {
            None => Backend::auto(),
            Some(Backend::Cuda { .. }) => Backend::Cuda { device },
            Some(backend) => backend,
        }
    }
}

/// The value parser of `--backend`: `auto`, or `cpu` or `cuda` read by the library's `FromStr`.
pub fn backend() -> impl TypedValueParser<Value = BackendFlag> {
    let values = [
        PossibleValue::new("auto")
            .help("CUDA when compiled in and a device is usable, else the CPU"),
        PossibleValue::new("cpu").help("The rayon CPU backend"),
        PossibleValue::new("cuda").help("The CUDA backend (an error if it cannot run here)"),
    ];
    PossibleValuesParser::new(values).try_map(|name| match name.as_str() {
        "auto" => Ok(BackendFlag::AUTO), // probed when the command runs, not while reading flags
        _ => name.parse().map(BackendFlag::named),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Arg, Command};

    fn parse<P: TypedValueParser>(parser: P, value: &str) -> Result<P::Value, clap::Error> {
        let cmd = Command::new("clatch");
        parser.parse_ref(&cmd, Some(&Arg::new("flag")), std::ffi::OsStr::new(value))
    }

    #[test]
    fn option_names_are_the_library_s() {
        use clatch::{LevelBudget, Ranking, Smoothing, Subpixel};
        for &s in Smoothing::VALUES {
            assert_eq!(parse(named::<Smoothing>(), s.name()).unwrap(), s);
        }
        assert_eq!(
            parse(named::<LevelBudget>(), "global").unwrap(),
            LevelBudget::Global
        );
        assert_eq!(
            parse(named::<Ranking>(), "harris").unwrap(),
            Ranking::Harris
        );
        assert_eq!(parse(named::<Subpixel>(), "none").unwrap(), Subpixel::None);
        assert!(parse(named::<Subpixel>(), "corner").is_err());
        let listed: Vec<_> = named::<Smoothing>()
            .possible_values()
            .into_iter()
            .flatten()
            .map(|v| v.get_name().to_string())
            .collect();
        assert_eq!(listed, ["none", "binomial3", "binomial5"]);
    }

    #[test]
    fn backend_names_are_auto_cpu_and_cuda() {
        assert_eq!(parse(backend(), "auto").unwrap(), BackendFlag::AUTO);
        assert_eq!(parse(backend(), "cpu").unwrap().backend(3), Backend::Cpu);
        assert_eq!(
            parse(backend(), "cuda").unwrap().backend(3),
            Backend::Cuda { device: 3 }
        );
        for wrong in ["tpu", "CPU", "cuda:1", ""] {
            assert!(parse(backend(), wrong).is_err(), "{wrong:?}");
        }
    }
}
