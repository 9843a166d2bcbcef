//! The `COCOG_*` code-path switches, which time one kernel against another on a GPU. Each takes
//! a few values; unset or empty keeps the default. Anything else keeps the default too and is
//! said on stderr once a process, however many renderers and compositors read the switch: a
//! mistyped experiment should not stop a training, nor fill its log.

use std::collections::BTreeSet;
use std::sync::Mutex;

/// `var` read by `parse`, or `default` where it is unset, empty or not understood (then said
/// once: `expected` names what it takes, `fallback` what runs instead).
pub fn env_switch<T>(
    var: &'static str,
    expected: &str,
    fallback: &str,
    default: T,
    parse: impl FnOnce(&str) -> Option<T>,
) -> T {
    let value = match std::env::var(var) {
        Ok(v) if !v.is_empty() => v,
        _ => return default,
    };
    match parse(&value) {
        Some(v) => v,
        None => {
            warn_once(
                var,
                &format!("{var}={value}: expected {expected}; {fallback}"),
            );
            default
        }
    }
}

/// `env_switch` over a list of names and what each selects.
pub fn env_choice<T: Copy>(
    var: &'static str,
    choices: &[(&str, T)],
    fallback: &str,
    default: T,
) -> T {
    let names: Vec<&str> = choices.iter().map(|(n, _)| *n).collect();
    let expected = match names.split_last() {
        Some((last, [])) => (*last).to_owned(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => "nothing".to_owned(),
    };
    env_switch(var, &expected, fallback, default, |v| {
        choices.iter().find(|(n, _)| *n == v).map(|(_, t)| *t)
    })
}

/// `message` on stderr, the first time a process says anything about `key`.
pub fn warn_once(key: &'static str, message: &str) {
    static SAID: Mutex<BTreeSet<&'static str>> = Mutex::new(BTreeSet::new());
    // A poisoned set only means a panic elsewhere while it was held; saying twice is harmless.
    let first = SAID.lock().map(|mut said| said.insert(key)).unwrap_or(true);
    if first {
        eprintln!("{message}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Each test uses a variable of its own: tests share the process environment.
    #[test]
    fn unset_and_empty_keep_the_default_and_names_select() {
        let choices = [("a", 1), ("b", 2)];
        assert_eq!(env_choice("COCOG_TEST_SWITCH_UNSET", &choices, "", 7), 7);
        // SAFETY: no other test reads or writes these variables.
        unsafe { std::env::set_var("COCOG_TEST_SWITCH_EMPTY", "") };
        assert_eq!(env_choice("COCOG_TEST_SWITCH_EMPTY", &choices, "", 7), 7);
        unsafe { std::env::set_var("COCOG_TEST_SWITCH_B", "b") };
        assert_eq!(env_choice("COCOG_TEST_SWITCH_B", &choices, "", 7), 2);
        unsafe { std::env::set_var("COCOG_TEST_SWITCH_BAD", "c") };
        assert_eq!(env_choice("COCOG_TEST_SWITCH_BAD", &choices, "", 7), 7);
    }

    #[test]
    fn a_parsed_switch_falls_back_where_the_parse_fails() {
        unsafe { std::env::set_var("COCOG_TEST_SWITCH_NUM", "12") };
        let parse = |v: &str| v.parse::<u32>().ok().filter(|n| *n <= 8);
        assert_eq!(
            env_switch("COCOG_TEST_SWITCH_NUM", "1 to 8", "", 3, parse),
            3
        );
        unsafe { std::env::set_var("COCOG_TEST_SWITCH_NUM2", "5") };
        assert_eq!(
            env_switch("COCOG_TEST_SWITCH_NUM2", "1 to 8", "", 3, parse),
            5
        );
    }
}
