//! Flags renamed so that one name means one thing in every command
//! (`--model` a weight file, `--noise-model` a noise model kind, `--noise`
//! noise values): the old spellings still parse (clap aliases) for one
//! release, and a one-line note names the new one.

/// (command, old spelling, new spelling).
const RENAMED: [(&str, &str, &str); 3] = [
    ("synth", "--model", "--noise-model"),
    ("train", "--noise", "--noise-model"),
    ("eval", "--noise", "--noise-model"),
];

/// The notes for the old spellings among `args` of `command`.
pub fn notes(command: &str, args: &[String]) -> Vec<String> {
    RENAMED
        .iter()
        .filter(|(c, old, _)| {
            *c == command
                && args
                    .iter()
                    .any(|a| a == old || a.starts_with(&format!("{old}=")))
        })
        .map(|(c, old, new)| {
            format!("`{c} {old}` is now `{c} {new}`; the old spelling goes in the next release")
        })
        .collect()
}
