//! `pgrf train`'s flags over its configuration file, with no code per
//! setting: [`TrainConfig`] is itself the flags (its doc comments are their
//! help), and [`TrainFlags`] remembers which ones the user gave, so that
//! exactly those replace the file's values ([`TrainConfig::with_flags`]).
//! Behind the `clap` feature, which the command-line crate enables.

use crate::config::{Method, TrainConfig};
use crate::error::Result;
use clap::parser::ValueSource;
use clap::{ArgMatches, Args, Command, FromArgMatches};
use std::path::Path;

/// [`TrainConfig`]'s flags as parsed: every setting (the defaults where a
/// flag was not given) and the keys of the flags given on the command line.
/// Flatten it into a command's arguments (`#[command(flatten)]`).
#[derive(Clone, Debug, Default)]
pub struct TrainFlags {
    /// Every setting: the flags given, the defaults for the others.
    pub values: TrainConfig,
    /// The settings given on the command line, by key (`ratio_min`).
    pub given: Vec<String>,
}

impl FromArgMatches for TrainFlags {
    fn from_arg_matches(m: &ArgMatches) -> std::result::Result<Self, clap::Error> {
        let values = TrainConfig::from_arg_matches(m)?;
        let given = m
            .ids()
            .map(|id| id.as_str())
            .filter(|id| m.value_source(id) == Some(ValueSource::CommandLine))
            .map(String::from)
            .collect();
        Ok(TrainFlags { values, given })
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> std::result::Result<(), clap::Error> {
        *self = TrainFlags::from_arg_matches(m)?;
        Ok(())
    }
}

impl Args for TrainFlags {
    fn augment_args(cmd: Command) -> Command {
        TrainConfig::augment_args(cmd)
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        TrainConfig::augment_args_for_update(cmd)
    }
}

impl TrainFlags {
    /// The settings given on the command line as a TOML table, the keys a
    /// configuration file would use.
    pub fn given_table(&self) -> Result<toml::Table> {
        let all = toml::Table::try_from(&self.values)
            .map_err(|e| crate::NnError::Config(e.to_string()))?;
        Ok(all
            .into_iter()
            .filter(|(key, _)| self.given.iter().any(|g| g == key))
            .collect())
    }

    /// `pgrf train`'s configuration: the defaults, then the `--config` file
    /// `file` (if any), then these flags, checked for training `method`.
    pub fn merge(&self, file: Option<&Path>, method: Method) -> Result<TrainConfig> {
        TrainConfig::merged(file, &self.given_table()?, method)
    }
}

impl TrainConfig {
    /// This configuration with the settings of the flags the user gave
    /// replacing its own (checked like a file).
    pub fn with_flags(&self, flags: &TrainFlags) -> Result<TrainConfig> {
        self.overlay(&flags.given_table()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        flags: TrainFlags,
    }

    #[test]
    fn the_flags_default_to_the_configuration_defaults() {
        let cli = Cli::try_parse_from(["pgrf"]).unwrap();
        assert_eq!(cli.flags.values, TrainConfig::default());
        assert!(cli.flags.given.is_empty());
    }

    #[test]
    fn only_the_flags_given_replace_the_file() {
        let cli = Cli::try_parse_from([
            "pgrf",
            "--steps",
            "99",
            "--no-augment",
            "--iso-range",
            "800,3200",
            "-o",
            "m.safetensors",
        ])
        .unwrap();
        let file = TrainConfig::from_toml("steps = 10\nbatch = 3\nseed = 5\n").unwrap();
        let c = file.with_flags(&cli.flags).unwrap();
        assert_eq!((c.steps, c.batch, c.seed, c.lr), (99, 3, 5, 1e-4));
        assert!(c.no_augment);
        assert_eq!(c.iso_range, Some(vec![800, 3200]));
        assert_eq!(
            c.output.as_deref(),
            Some(std::path::Path::new("m.safetensors"))
        );
        // A flag given with its default value still replaces the file's.
        let cli = Cli::try_parse_from(["pgrf", "--batch", "1", "--no-augment", "false"]).unwrap();
        let file = TrainConfig::from_toml("batch = 3\nno_augment = true\n").unwrap();
        let c = file.with_flags(&cli.flags).unwrap();
        assert_eq!((c.batch, c.no_augment), (1, false));
    }
}
