//! Declaring parameters once: [`parameters!`] turns one list of typed fields, each with its
//! default, range, unit and one-line meaning, into the typed struct the models read, the
//! documented table (`arch show`, TOML and `--set` validation, reports) and the conversion
//! from the table's values to the struct. A group of parameters two machines share (the
//! Occlusion Unit's) is declared once and composed into both. Every parameter carries its
//! provenance: `V "source"` (read in a primary source), `V2 "source"` (a secondary source) or
//! `I [low, high] "reason"` (our inference, with the plausible range the sensitivity
//! analysis varies it over, in the parameter's unit).

use super::{Mark, Param, ParamKind, Provenance, Value};

/// A Rust type a parameter can have: how its default and range become a table entry, and
/// how a table value becomes the type again.
pub trait ParamType: Sized + Copy {
    /// The table's value and kind for a default and an optional inclusive range.
    fn declare(default: Self, range: Option<(Self, Self)>) -> (Value, ParamKind);
    /// The table value of one value of this type.
    fn to_value(self) -> Value;
    /// The typed value of a table value of the kind [`ParamType::declare`] gave.
    fn from_value(value: Value) -> Self;
}

/// Why a value can have only the kind its own type declared: `Arch` sets values only through
/// `parse_value`, which follows the parameter's kind.
const KIND_FOLLOWS_TYPE: &str = "a parameter's value has the kind its type declared";

macro_rules! integer_param_type {
    ($($t:ty),*) => {$(
        impl ParamType for $t {
            fn declare(default: $t, range: Option<($t, $t)>) -> (Value, ParamKind) {
                let (min, max) = range.unwrap_or((<$t>::MIN, <$t>::MAX));
                (Value::Int(default as u64), ParamKind::Int { min: min as u64, max: max as u64 })
            }
            fn to_value(self) -> Value {
                Value::Int(self as u64)
            }
            fn from_value(value: Value) -> $t {
                match value {
                    Value::Int(v) => v as $t,
                    _ => unreachable!("{KIND_FOLLOWS_TYPE}"),
                }
            }
        }
    )*};
}

integer_param_type!(u64, usize, u32);

impl ParamType for f64 {
    fn declare(default: f64, range: Option<(f64, f64)>) -> (Value, ParamKind) {
        let (min, max) = range.unwrap_or((f64::MIN, f64::MAX));
        (Value::Float(default), ParamKind::Float { min, max })
    }
    fn to_value(self) -> Value {
        Value::Float(self)
    }
    fn from_value(value: Value) -> f64 {
        match value {
            Value::Float(v) => v,
            _ => unreachable!("{KIND_FOLLOWS_TYPE}"),
        }
    }
}

impl ParamType for bool {
    fn declare(default: bool, _: Option<(bool, bool)>) -> (Value, ParamKind) {
        (Value::Bool(default), ParamKind::Bool)
    }
    fn to_value(self) -> Value {
        Value::Bool(self)
    }
    fn from_value(value: Value) -> bool {
        match value {
            Value::Bool(v) => v,
            _ => unreachable!("{KIND_FOLLOWS_TYPE}"),
        }
    }
}

/// A parameter that is one of a fixed set of names, as an enum.
pub trait Named: Sized + Copy + 'static {
    /// Every variant, in the order of [`Named::NAMES`].
    const ALL: &'static [Self];
    const NAMES: &'static [&'static str];
}

impl<T: Named + PartialEq> ParamType for T {
    fn declare(default: T, _: Option<(T, T)>) -> (Value, ParamKind) {
        let index = T::ALL.iter().position(|v| *v == default).unwrap_or(0);
        (
            Value::Choice(T::NAMES[index]),
            ParamKind::Choice { choices: T::NAMES },
        )
    }
    fn to_value(self) -> Value {
        let index = T::ALL.iter().position(|v| *v == self).unwrap_or(0);
        Value::Choice(T::NAMES[index])
    }
    fn from_value(value: Value) -> T {
        match value {
            Value::Choice(name) => {
                let index = T::NAMES.iter().position(|n| *n == name).unwrap_or(0);
                T::ALL[index]
            }
            _ => unreachable!("{KIND_FOLLOWS_TYPE}"),
        }
    }
}

/// One table entry from a field's declaration.
///
/// # Panics
/// On a declaration that breaks the provenance rules (a programming error, found by every
/// test that builds a table): an inference without a plausible range, a sourced value with
/// one, or a plausible range that is reversed, outside the legal range or without the default.
pub fn param<T: ParamType>(
    key: &'static str,
    unit: &'static str,
    default: T,
    range: Option<(T, T)>,
    meaning: &'static str,
    (mark, plausible, source): (Mark, Option<(T, T)>, &'static str),
) -> Param {
    let (default, kind) = T::declare(default, range);
    let plausible = plausible.map(|(low, high)| (low.to_value(), high.to_value()));
    let param = Param {
        key,
        unit,
        default,
        kind,
        meaning,
        provenance: Provenance {
            mark,
            plausible,
            source,
        },
    };
    if let Err(why) = param.check_provenance() {
        panic!("parameter {key}: {why}");
    }
    param
}

/// Reads a table's values in order into typed fields.
pub struct Cursor<'v> {
    values: &'v [Value],
    at: usize,
}

impl<'v> Cursor<'v> {
    pub fn new(values: &'v [Value]) -> Cursor<'v> {
        Cursor { values, at: 0 }
    }

    pub fn next<T: ParamType>(&mut self) -> T {
        let value = self.values[self.at];
        self.at += 1;
        T::from_value(value)
    }

    /// A group's fields, read by the group's own `from_cursor`.
    pub fn group<G>(&mut self, read: impl FnOnce(&mut Cursor<'v>) -> G) -> G {
        read(self)
    }
}

/// Declare a struct of parameters:
/// `key: type = default, [min, max], "unit", "meaning", MARK [low, high] "source";`
/// (the legal range only for numbers; MARK is `V`, `V2` or `I`, and the plausible range
/// `[low, high]` is given for `I` alone), optionally followed by `group name: Type;` and more
/// fields. Generates the struct, `fn table() -> Vec<Param>` in declaration order (a group's
/// entries where it stands) and `fn from_cursor`.
macro_rules! parameters {
    (
        $(#[$doc:meta])*
        pub struct $name:ident {
            $( $field:ident : $ty:ty = $default:expr, $([$min:expr, $max:expr],)? $unit:literal, $meaning:literal,
               $mark:ident $([$low:expr, $high:expr])? $source:literal; )*
        }
        $( group $group:ident : $group_ty:ty; {
            $( $after:ident : $after_ty:ty = $after_default:expr, $([$after_min:expr, $after_max:expr],)? $after_unit:literal, $after_meaning:literal,
               $after_mark:ident $([$after_low:expr, $after_high:expr])? $after_source:literal; )*
        } )?
    ) => {
        $(#[$doc])*
        #[derive(Clone, Debug, PartialEq)]
        pub struct $name {
            $( #[doc = $meaning] pub $field: $ty, )*
            $(
                #[doc = concat!("The ", stringify!($group), " parameters.")]
                pub $group: $group_ty,
                $( #[doc = $after_meaning] pub $after: $after_ty, )*
            )?
        }

        impl $name {
            /// The documented table, in declaration order.
            pub fn table() -> Vec<$crate::arch::Param> {
                #[allow(unused_mut)]
                let mut table = vec![
                    $( $crate::arch::declare::param::<$ty>(
                        stringify!($field), $unit, $default,
                        None $(.or(Some(($min, $max))))?, $meaning,
                        ($crate::arch::Mark::$mark, None $(.or(Some(($low, $high))))?, $source),
                    ), )*
                ];
                $(
                    table.extend(<$group_ty>::table());
                    $( table.push($crate::arch::declare::param::<$after_ty>(
                        stringify!($after), $after_unit, $after_default,
                        None $(.or(Some(($after_min, $after_max))))?, $after_meaning,
                        ($crate::arch::Mark::$after_mark, None $(.or(Some(($after_low, $after_high))))?, $after_source),
                    )); )*
                )?
                table
            }

            /// The typed parameters from a table's values, read in declaration order.
            pub fn from_cursor(cursor: &mut $crate::arch::declare::Cursor<'_>) -> $name {
                $name {
                    $( $field: cursor.next(), )*
                    $(
                        $group: cursor.group(<$group_ty>::from_cursor),
                        $( $after: cursor.next(), )*
                    )?
                }
            }
        }
    };
}

pub(crate) use parameters;

#[cfg(test)]
mod tests {
    use super::super::{Mark, ParamKind, Value};
    use super::*;

    parameters! {
        /// A group.
        pub struct Inner {
            b: bool = true, "bool", "inner flag", V "a source";
        }
    }

    parameters! {
        /// Fields, a group, more fields.
        pub struct Outer {
            a: u32 = 7, [1, 9], "things", "first", I [2, 8] "a guess";
            x: f64 = 0.5, [0.0, 1.0], "share", "second", V2 "a book";
        }
        group inner: Inner; {
            z: usize = 3, "slots", "last, unbounded", I [1, 5] "another guess";
        }
    }

    #[test]
    fn one_declaration_gives_the_table_in_order_and_the_typed_struct() {
        let table = Outer::table();
        let keys: Vec<&str> = table.iter().map(|p| p.key).collect();
        assert_eq!(keys, ["a", "x", "b", "z"]);
        assert_eq!(table[0].kind, ParamKind::Int { min: 1, max: 9 });
        assert_eq!(table[1].kind, ParamKind::Float { min: 0.0, max: 1.0 });
        assert_eq!(table[2].default, Value::Bool(true));
        assert_eq!(
            table[3].kind,
            ParamKind::Int {
                min: 0,
                max: usize::MAX as u64
            }
        );
        assert_eq!((table[0].unit, table[0].meaning), ("things", "first"));
        assert_eq!(table[0].provenance.mark, Mark::I);
        assert_eq!(
            table[0].provenance.plausible,
            Some((Value::Int(2), Value::Int(8)))
        );
        assert_eq!(
            (table[1].provenance.mark, table[1].provenance.source),
            (Mark::V2, "a book")
        );
        assert_eq!(table[2].provenance.plausible, None);
        let values = [
            Value::Int(2),
            Value::Float(0.25),
            Value::Bool(false),
            Value::Int(5),
        ];
        let outer = Outer::from_cursor(&mut Cursor::new(&values));
        assert_eq!(
            outer,
            Outer {
                a: 2,
                x: 0.25,
                inner: Inner { b: false },
                z: 5
            }
        );
    }

    #[test]
    #[should_panic(expected = "parameter a: an inference needs a plausible range")]
    fn an_inference_without_a_range_is_refused() {
        param::<u32>(
            "a",
            "things",
            7,
            Some((1, 9)),
            "first",
            (Mark::I, None, "a guess"),
        );
    }

    #[test]
    #[should_panic(expected = "does not hold the default")]
    fn a_plausible_range_must_hold_the_default() {
        param::<u32>(
            "a",
            "things",
            7,
            Some((1, 9)),
            "first",
            (Mark::I, Some((1, 5)), "a guess"),
        );
    }

    #[test]
    #[should_panic(expected = "outside the legal range")]
    fn a_plausible_range_must_be_legal() {
        param::<u32>(
            "a",
            "things",
            7,
            Some((1, 9)),
            "first",
            (Mark::I, Some((2, 10)), "a guess"),
        );
    }

    #[test]
    #[should_panic(expected = "only an inference has a plausible range")]
    fn a_sourced_value_has_no_range() {
        param::<u32>(
            "a",
            "things",
            7,
            Some((1, 9)),
            "first",
            (Mark::V, Some((2, 8)), "a paper"),
        );
    }
}
