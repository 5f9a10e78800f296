//! Stage settings as config files and command lines spell them: `off`, `on`
//! (the stage's defaults) or a comma list of `KEY=VALUE` over the defaults.

/// Parses `s` for the stage called `what` (it starts every message): `off`
/// is `None`, `on` the defaults; otherwise each `KEY=VALUE` (a number) goes
/// to `set` over the defaults, which rejects keys it does not know, and
/// `validate` checks the result.
pub fn parse_on_off<T: Default>(
    s: &str,
    what: &str,
    mut set: impl FnMut(&mut T, &str, f64) -> Result<(), String>,
    validate: impl Fn(&T) -> Result<(), String>,
) -> Result<Option<T>, String> {
    match s {
        "off" => return Ok(None),
        "on" => return Ok(Some(T::default())),
        _ => {}
    }
    let mut c = T::default();
    for item in s.split(',') {
        let (key, value) =
            item.split_once('=').ok_or_else(|| format!("{what}: `{item}` is not KEY=VALUE (or use `on` / `off`)"))?;
        let v: f64 = value.trim().parse().map_err(|_| format!("{what}: `{key}` needs a number, got `{value}`"))?;
        set(&mut c, key.trim(), v).map_err(|m| format!("{what}: {m}"))?;
    }
    validate(&c).map_err(|m| format!("{what}: {m}"))?;
    Ok(Some(c))
}
