//! Words for the counts the tools print: "1 frame", "2 frames".

/// `n` and the noun that counts it: `singular` for one, else `plural` (`counted(1, "query",
/// "queries")` is "1 query"; it had printed "1 frames", "in 1 blocks").
pub fn counted(n: u64, singular: &str, plural: &str) -> String {
    match n {
        1 => format!("1 {singular}"),
        _ => format!("{n} {plural}"),
    }
}

#[cfg(test)]
mod tests {
    use super::counted;

    #[test]
    fn one_takes_the_singular_and_every_other_count_the_plural() {
        assert_eq!(counted(1, "frame", "frames"), "1 frame");
        assert_eq!(counted(0, "frame", "frames"), "0 frames");
        assert_eq!(counted(2, "query", "queries"), "2 queries");
    }
}
