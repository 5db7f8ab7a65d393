//! The `with_*` methods of the public settings types (`#[non_exhaustive]`, so built from their
//! defaults): each returns the value with one field replaced.

/// Writes `with_*` methods, one per `$(#[doc])* method => field: Type;` line: consuming, `#[must_use]`,
/// the value with `field` replaced and every other field kept.
macro_rules! with_methods {
    ($($(#[$doc:meta])* $method:ident => $field:ident: $ty:ty;)+) => {$(
        $(#[$doc])*
        #[must_use]
        pub fn $method(self, $field: $ty) -> Self {
            Self { $field, ..self }
        }
    )+};
}
