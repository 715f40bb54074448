//! The names Python callers know the library's parameters by. The library names a parameter as
//! its options structs do (the `name` of `vcsmooth::Error::Parameter`: `lambda`, `patch_size`,
//! …); the keyword arguments of [`crate::options`] take those names, but for the few in
//! [`RENAMED`]. [`keyword`] maps one to the other for the messages of [`crate::errors`].

/// Library parameter name → keyword argument, for the parameters whose keyword is another name.
/// A keyword added to `options::KWARGS` under a name other than the library's needs its line here.
const RENAMED: &[(&str, &str)] = &[
    // `lambda` is a Python keyword.
    ("lambda", "lam"),
    // `EngineSettings::pins`, whichever way they come; `pinned` is the arrays' keyword, beside
    // the files' `pin` and `pin_property`.
    ("pins", "pinned"),
];

/// The keyword argument that sets the library's parameter `library` (as errors name it), or
/// `library` itself when its keyword has the same name (or no keyword sets it).
pub fn keyword(library: &str) -> &str {
    RENAMED
        .iter()
        .find(|(l, _)| *l == library)
        .map_or(library, |(_, k)| k)
}
