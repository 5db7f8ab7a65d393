//! Options by name: the one spelling table of each option enum of the configuration, which `FromStr`
//! reads and `Display` writes, so that a command line, a binding or a config file need no table of
//! their own.

use std::fmt;

/// An option enum of the configuration whose values have names ([`crate::Subpixel`],
/// [`crate::Ranking`], [`crate::LevelBudget`], [`crate::Smoothing`]): `FromStr` reads the names,
/// `Display` writes them, and [`NamedOption::VALUES`] lists every value, for a command line's help or
/// a binding's documentation.
///
/// ```
/// use clatch::{NamedOption, Smoothing};
///
/// assert_eq!("binomial5".parse::<Smoothing>()?, Smoothing::Binomial5);
/// assert_eq!(Smoothing::Binomial3.to_string(), "binomial3");
/// let names: Vec<_> = Smoothing::VALUES.iter().map(|s| s.name()).collect();
/// assert_eq!(names, ["none", "binomial3", "binomial5"]);
///
/// let error = "gauss".parse::<Smoothing>().unwrap_err();
/// assert_eq!(error.accepted(), ["none", "binomial3", "binomial5"]);
/// assert_eq!(
///     error.to_string(),
///     r#"smoothing must be one of "none", "binomial3", "binomial5", got "gauss""#
/// );
/// # Ok::<(), clatch::ParseNameError>(())
/// ```
///
/// The trait is sealed: only clatch's option enums implement it.
pub trait NamedOption:
    Copy
    + Eq
    + std::str::FromStr<Err = ParseNameError>
    + fmt::Display
    + Send
    + Sync
    + 'static
    + sealed::Sealed
{
    /// The option's name: its field in the configuration (`"level_budget"`).
    const OPTION: &'static str;
    /// Every value, in the order their names are listed.
    const VALUES: &'static [Self];
    /// The value's name, as `FromStr` reads it and `Display` writes it: lowercase ASCII (`"score"`).
    fn name(self) -> &'static str;
    /// One line saying what the value does.
    fn summary(self) -> &'static str;
}

mod sealed {
    /// Keeps [`super::NamedOption`] to clatch's own enums, so that it can grow.
    pub trait Sealed {}
}

/// A name that is not one of an option's (or a backend's): says which option, what was given and
/// which names are accepted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseNameError {
    option: &'static str,
    given: String,
    accepted: Vec<&'static str>,
}

impl ParseNameError {
    /// The error for `given`, not a name of `option`, whose names are `accepted`.
    pub(crate) fn new(option: &'static str, given: &str, accepted: Vec<&'static str>) -> Self {
        Self {
            option,
            given: given.to_string(),
            accepted,
        }
    }

    /// The option: its field in the configuration (`"smoothing"`, `"backend"`).
    pub fn option(&self) -> &'static str {
        self.option
    }

    /// The text that was given.
    pub fn given(&self) -> &str {
        &self.given
    }

    /// The names accepted, in the order the option lists them.
    pub fn accepted(&self) -> &[&'static str] {
        &self.accepted
    }
}

/// Formats as `smoothing must be one of "none", "binomial3", "binomial5", got "gauss"`.
impl fmt::Display for ParseNameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} must be one of ", self.option)?;
        for (i, name) in self.accepted.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{name:?}")?;
        }
        write!(f, ", got {:?}", self.given)
    }
}

impl std::error::Error for ParseNameError {}

/// The value of `T` named `name`.
fn parse<T: NamedOption>(name: &str) -> Result<T, ParseNameError> {
    T::VALUES
        .iter()
        .copied()
        .find(|v| v.name() == name)
        .ok_or_else(|| {
            ParseNameError::new(
                T::OPTION,
                name,
                T::VALUES.iter().map(|v| v.name()).collect(),
            )
        })
}

/// The spelling table of an option enum: its option name, and per value its name and a one-line
/// summary. Implements [`NamedOption`], `FromStr` and `Display`. `VALUES` and the two matches come
/// from the one list, and the matches have no wildcard: a variant left out does not compile.
macro_rules! named_option {
    ($type:ty, $option:literal, { $($value:path => $name:literal: $summary:literal,)+ }) => {
        impl sealed::Sealed for $type {}

        impl NamedOption for $type {
            const OPTION: &'static str = $option;
            const VALUES: &'static [Self] = &[$($value),+];

            fn name(self) -> &'static str {
                match self {
                    $($value => $name,)+
                }
            }

            fn summary(self) -> &'static str {
                match self {
                    $($value => $summary,)+
                }
            }
        }

        /// Reads the names of [`NamedOption::name`].
        impl std::str::FromStr for $type {
            type Err = ParseNameError;

            fn from_str(name: &str) -> Result<Self, ParseNameError> {
                parse(name)
            }
        }

        /// Writes [`NamedOption::name`].
        impl fmt::Display for $type {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

named_option!(crate::Subpixel, "subpixel", {
    crate::Subpixel::None => "none": "Whole pixels",
    crate::Subpixel::Score => "score": "The peak of the FAST score, per axis",
});

named_option!(crate::Ranking, "ranking", {
    crate::Ranking::Fast => "fast": "The FAST score",
    crate::Ranking::Harris => "harris": "The Harris response, as ORB ranks",
});

named_option!(crate::LevelBudget, "level_budget", {
    crate::LevelBudget::Global => "global": "The strongest keypoints of all levels together",
    crate::LevelBudget::Geometric => "geometric": "ORB's geometric shares per level",
    crate::LevelBudget::Area => "area": "Shares in proportion to each level's pixels",
});

named_option!(crate::Smoothing, "smoothing", {
    crate::Smoothing::None => "none": "No smoothing",
    crate::Smoothing::Binomial3 => "binomial3": "[1 2 1] on both axes (3x3)",
    crate::Smoothing::Binomial5 => "binomial5":
        "[1 4 6 4 1] on both axes (5x5, about a Gaussian of sigma 1 pixel)",
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{LevelBudget, Ranking, Smoothing, Subpixel};

    /// Every value's name reads back as the value, `Display` writes the name, the names are distinct
    /// lowercase words, and an unknown name lists them all.
    fn round_trips<T: NamedOption + fmt::Debug>(expected_names: &[&str]) {
        let names: Vec<_> = T::VALUES.iter().map(|v| v.name()).collect();
        assert_eq!(names, expected_names, "{}", T::OPTION);
        for &value in T::VALUES {
            assert_eq!(value.name().parse::<T>(), Ok(value));
            assert_eq!(value.to_string(), value.name());
            assert!(!value.summary().is_empty());
        }
        for wrong in ["", "NONE", " none", "none ", "x"] {
            let error = wrong.parse::<T>().unwrap_err();
            assert_eq!(error.option(), T::OPTION);
            assert_eq!(error.given(), wrong);
            assert_eq!(error.accepted(), expected_names);
        }
    }

    #[test]
    fn every_option_reads_back_what_it_writes() {
        round_trips::<Subpixel>(&["none", "score"]);
        round_trips::<Ranking>(&["fast", "harris"]);
        round_trips::<LevelBudget>(&["global", "geometric", "area"]);
        round_trips::<Smoothing>(&["none", "binomial3", "binomial5"]);
    }

    #[test]
    fn the_error_names_the_option_and_quotes_the_names() {
        let error = "orb".parse::<LevelBudget>().unwrap_err();
        assert_eq!(
            error.to_string(),
            r#"level_budget must be one of "global", "geometric", "area", got "orb""#
        );
    }
}
