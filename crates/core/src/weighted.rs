//! Comma-separated lists of `ITEM[@WEIGHT]` entries, the form of training
//! mixes (`--data photos@3,procedural@1`, `--profile sony-a7s2@3,nikon-d850`):
//! one parser, so every such flag accepts and refuses the same texts.

/// Why a list does not parse; callers word the message for their flag.
#[derive(Clone, Debug, PartialEq)]
pub enum WeightedError {
    /// An entry is empty (two commas, a trailing comma, an empty text).
    Empty,
    /// The weight after `@` of this entry is not a positive finite number.
    BadWeight(String),
}

/// The `(item, weight)` entries of `text`, items and weights trimmed,
/// weight 1 where none is given. The item may be empty (`@2`): whether that
/// is allowed is the caller's to say.
pub fn parse_weighted(text: &str) -> Result<Vec<(&str, f64)>, WeightedError> {
    text.split(',')
        .map(|raw| {
            let item = raw.trim();
            if item.is_empty() {
                return Err(WeightedError::Empty);
            }
            match item.rsplit_once('@') {
                Some((name, w)) => match w.trim().parse::<f64>() {
                    Ok(v) if v.is_finite() && v > 0.0 => Ok((name.trim(), v)),
                    _ => Err(WeightedError::BadWeight(item.to_string())),
                },
                None => Ok((item, 1.0)),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_weights_and_refusals() {
        assert_eq!(
            parse_weighted(" a@3 , b ,c@0.5").unwrap(),
            vec![("a", 3.0), ("b", 1.0), ("c", 0.5)]
        );
        assert_eq!(parse_weighted("@2").unwrap(), vec![("", 2.0)]);
        for bad in ["", "a,", "a,,b"] {
            assert_eq!(parse_weighted(bad), Err(WeightedError::Empty), "{bad:?}");
        }
        for bad in ["a@0", "a@-1", "a@x", "a@nan", "a@inf"] {
            assert_eq!(
                parse_weighted(bad),
                Err(WeightedError::BadWeight(bad.into())),
                "{bad:?}"
            );
        }
    }
}
