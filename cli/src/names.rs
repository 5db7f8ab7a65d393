//! Flags that take the library's names: the option enums ([`clatch::NamedOption`]: `--subpixel`,
//! `--ranking`, `--level-budget`, `--smoothing`) and `--backend`. The names, their help and their
//! parsing are the library's; this file only hands them to clap.

use std::ffi::OsStr;
use std::marker::PhantomData;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clatch::{Backend, NamedOption};

/// The value parser of a flag taking an option enum `T`: `T`'s names as clap's possible values (with
/// their summaries in `--help`; a wrong name refused with the list and the closest name), read by
/// `T`'s `FromStr`.
#[derive(Clone, Copy, Debug)]
pub struct Named<T>(PhantomData<T>);

impl<T: NamedOption> Named<T> {
    /// The parser of `T`'s names.
    pub fn new() -> Self {
        Self(PhantomData)
    }
}

impl<T: NamedOption> TypedValueParser for Named<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<T, clap::Error> {
        let names = T::VALUES.iter().map(|v| v.name());
        let name = PossibleValuesParser::new(names).parse_ref(cmd, arg, value)?;
        name.parse()
            .map_err(|e| clap::Error::raw(clap::error::ErrorKind::InvalidValue, e).with_cmd(cmd))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(
            T::VALUES
                .iter()
                .map(|v| PossibleValue::new(v.name()).help(v.summary())),
        ))
    }
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

/// The values `--backend` takes (the library reads all but `auto`), with their help.
fn backend_values() -> [PossibleValue; 3] {
    [
        PossibleValue::new("auto")
            .help("CUDA when compiled in and a device is usable, else the CPU"),
        PossibleValue::new("cpu").help("The rayon CPU backend"),
        PossibleValue::new("cuda").help("The CUDA backend (an error if it cannot run here)"),
    ]
}

/// The value parser of `--backend`.
#[derive(Clone, Copy, Debug)]
pub struct BackendParser;

impl TypedValueParser for BackendParser {
    type Value = BackendFlag;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<BackendFlag, clap::Error> {
        let name = PossibleValuesParser::new(backend_values()).parse_ref(cmd, arg, value)?;
        if name == "auto" {
            return Ok(BackendFlag::AUTO); // probed when the command runs, not while reading flags
        }
        name.parse()
            .map(BackendFlag::named)
            .map_err(|e| clap::Error::raw(clap::error::ErrorKind::InvalidValue, e).with_cmd(cmd))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(backend_values().into_iter()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Arg, Command};

    fn parse<P: TypedValueParser>(parser: P, value: &str) -> Result<P::Value, clap::Error> {
        let cmd = Command::new("clatch");
        parser.parse_ref(&cmd, Some(&Arg::new("flag")), OsStr::new(value))
    }

    #[test]
    fn option_names_are_the_library_s() {
        use clatch::{LevelBudget, Ranking, Smoothing, Subpixel};
        for &s in Smoothing::VALUES {
            assert_eq!(parse(Named::<Smoothing>::new(), s.name()).unwrap(), s);
        }
        assert_eq!(
            parse(Named::<LevelBudget>::new(), "global").unwrap(),
            LevelBudget::Global
        );
        assert_eq!(
            parse(Named::<Ranking>::new(), "harris").unwrap(),
            Ranking::Harris
        );
        assert_eq!(
            parse(Named::<Subpixel>::new(), "none").unwrap(),
            Subpixel::None
        );
        assert!(parse(Named::<Subpixel>::new(), "corner").is_err());
        let listed: Vec<_> = Named::<Smoothing>::new()
            .possible_values()
            .into_iter()
            .flatten()
            .map(|v| v.get_name().to_string())
            .collect();
        assert_eq!(listed, ["none", "binomial3", "binomial5"]);
    }

    #[test]
    fn backend_names_are_auto_cpu_and_cuda() {
        assert_eq!(parse(BackendParser, "auto").unwrap(), BackendFlag::AUTO);
        assert_eq!(
            parse(BackendParser, "cpu").unwrap().backend(3),
            Backend::Cpu
        );
        assert_eq!(
            parse(BackendParser, "cuda").unwrap().backend(3),
            Backend::Cuda { device: 3 }
        );
        for wrong in ["tpu", "CPU", "cuda:1", ""] {
            assert!(parse(BackendParser, wrong).is_err(), "{wrong:?}");
        }
    }
}
