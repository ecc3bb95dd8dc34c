//! Path safety: abysslight never writes over, into or around its inputs, and never follows a symbolic link out of
//! the output folder when writing.
//!
//! - [`resolve`] gives the one absolute form of a path that may not exist yet: the existing prefix is
//!   canonicalised (symbolic links resolved), the rest normalised lexically, and `..` after a folder that does not
//!   exist yet goes back to its parent (that is what the file system will do once the folder is created).
//! - [`check_outputs`] refuses any output (folder or file) that equals, lies inside, or contains an input.
//! - [`check_no_links_below`] refuses a write whose path crosses a symbolic link below the output folder.

use std::ffi::OsString;
use std::path::{Component, Path, PathBuf};

use crate::error::{Error, Result};

/// The absolute, normalised form of `p`, which need not exist: every existing leading component is resolved as
/// the file system resolves it (symbolic links followed, `..` taken after the link), the rest lexically.
pub fn resolve(p: &Path) -> PathBuf {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_owned());
    let mut out = PathBuf::new();
    // Components pushed lexically at the end of `out` that do not exist (yet).
    let mut pending: Vec<OsString> = Vec::new();
    for c in abs.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => out.push(c.as_os_str()),
            Component::CurDir => {}
            Component::ParentDir => {
                // Either a folder that does not exist yet (lexically), or an existing canonical one, whose
                // parent is where `..` leads.
                pending.pop();
                out.pop();
            }
            Component::Normal(name) => {
                if pending.is_empty() {
                    let next = out.join(name);
                    if std::fs::symlink_metadata(&next).is_ok() {
                        if let Ok(canon) = next.canonicalize() {
                            out = canon;
                            continue;
                        }
                    }
                }
                out.push(name);
                pending.push(name.to_owned());
            }
        }
    }
    out
}

/// How `a` relates to `b` once both are resolved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overlap {
    /// `a` and `b` are the same folder.
    Same,
    /// `a` lies inside `b`.
    Inside,
    /// `a` contains `b`.
    Contains,
}

/// The overlap of two paths, if any (both resolved with [`resolve`]).
pub fn overlap(a: &Path, b: &Path) -> Option<Overlap> {
    let (a, b) = (resolve(a), resolve(b));
    if a == b {
        Some(Overlap::Same)
    } else if a.starts_with(&b) {
        Some(Overlap::Inside)
    } else if b.starts_with(&a) {
        Some(Overlap::Contains)
    } else {
        None
    }
}

/// Refuse any output (`(flag, path)`: an output folder, a report file, ...) that equals, lies inside, or contains
/// an input (`(what, path)`: survey, water column, scatter image, mask, config file). Outputs are also checked
/// against each other where one is a file inside the other folder's tree is allowed (the report may go into
/// `--out`). The error names both paths and the relation.
pub fn check_outputs(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<()> {
    for (flag, out) in outputs {
        for (what, input) in inputs {
            let relation = match overlap(out, input) {
                None => continue,
                Some(Overlap::Same) => format!("is the {what} {}", input.display()),
                Some(Overlap::Inside) => format!("lies inside the {what} {}", input.display()),
                Some(Overlap::Contains) => format!("contains the {what} {}", input.display()),
            };
            return Err(Error::Usage(format!(
                "{flag} {} {relation} (resolved: {} and {}): abysslight never writes over, into or around its \
                 inputs; choose a path outside them",
                out.display(),
                resolve(out).display(),
                resolve(input).display()
            )));
        }
    }
    Ok(())
}

/// Refuse writing `target` if any existing component of it below `root` (the output folder; `root` itself may be
/// a link the user chose) is a symbolic link, or an existing parent is not a folder: the write could land outside
/// `root`. Components that do not exist yet are fine (they are created as real folders).
pub fn check_no_links_below(root: &Path, target: &Path) -> Result<()> {
    let Ok(rest) = target.strip_prefix(root) else {
        return Err(Error::Usage(format!(
            "{}: not inside the output folder {}",
            target.display(),
            root.display()
        )));
    };
    let mut at = root.to_path_buf();
    let parts: Vec<Component> = rest.components().collect();
    for (i, c) in parts.iter().enumerate() {
        match c {
            Component::Normal(name) => at.push(name),
            Component::CurDir => continue,
            _ => {
                return Err(Error::Usage(format!(
                    "{}: `..` or an absolute part below the output folder {}",
                    target.display(),
                    root.display()
                )))
            }
        }
        let meta = match std::fs::symlink_metadata(&at) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(Error::io(&at, e)),
        };
        let last = i + 1 == parts.len();
        if meta.file_type().is_symlink() {
            return Err(Error::io(
                &at,
                std::io::Error::other(format!(
                    "a symbolic link inside the output folder {}: abysslight does not write through links \
                     (the write could land outside the output folder); remove it or choose another --out",
                    root.display()
                )),
            ));
        }
        if !last && !meta.is_dir() {
            return Err(Error::io(
                &at,
                std::io::Error::other(
                    "exists and is not a folder, but the output needs a folder here",
                ),
            ));
        }
    }
    Ok(())
}

/// Whether `p` is `root` or lies below it, both resolved.
pub fn is_within(p: &Path, root: &Path) -> bool {
    matches!(overlap(p, root), Some(Overlap::Same | Overlap::Inside))
}

#[cfg(test)]
mod tests {
    use super::*;

    enum Step {
        Root,
        Up,
        Name(std::ffi::OsString),
    }

    fn steps(p: &Path) -> Vec<Step> {
        p.components()
            .filter_map(|c| match c {
                Component::RootDir | Component::Prefix(_) => Some(Step::Root),
                Component::ParentDir => Some(Step::Up),
                Component::Normal(n) => Some(Step::Name(n.to_owned())),
                Component::CurDir => None,
            })
            .collect()
    }

    /// An independent model of the kernel's path walk for [`resolve`]: components one by one, links expanded with
    /// `read_link` (no `canonicalize`), names that do not exist kept as they are.
    fn resolve_by_walking(p: &Path) -> PathBuf {
        let mut todo = steps(&std::path::absolute(p).unwrap());
        todo.reverse();
        let mut cur = PathBuf::from("/");
        let mut hops = 0;
        while let Some(step) = todo.pop() {
            match step {
                Step::Root => cur = PathBuf::from("/"),
                Step::Up => {
                    cur.pop();
                }
                Step::Name(n) => {
                    let next = cur.join(&n);
                    match std::fs::read_link(&next) {
                        Ok(target) if hops < 40 => {
                            hops += 1;
                            let mut more = steps(&target);
                            more.reverse();
                            todo.extend(more);
                        }
                        _ => cur = next,
                    }
                }
            }
        }
        cur
    }

    #[cfg(unix)]
    #[test]
    fn resolve_matches_a_component_walk() {
        let d = tempfile::tempdir().unwrap();
        let root = d.path().canonicalize().unwrap();
        std::fs::create_dir_all(root.join("a/b")).unwrap();
        std::fs::create_dir_all(root.join("survey")).unwrap();
        std::os::unix::fs::symlink(root.join("a/b"), root.join("link")).unwrap();
        std::os::unix::fs::symlink("a/b/../../survey", root.join("rel")).unwrap();
        let cases = [
            "survey",
            "nonexistent/../survey",
            "x/y/../../survey",
            "x/../y/../a/./b/..",
            "link/..",
            "link/../b",
            "rel/new",
            "a/b/c/d/../../..",
            "survey/",
            "survey/./IMG.jpg",
            "missing/../../",
        ];
        for c in cases {
            let p = root.join(c);
            assert_eq!(resolve(&p), resolve_by_walking(&p), "{c}");
        }
        // The case of issue 13: `..` after a folder that does not exist.
        assert_eq!(
            resolve(&root.join("nonexistent/../survey")),
            root.join("survey")
        );
        // `..` after a link goes to the link target's parent, as the kernel does.
        assert_eq!(resolve(&root.join("link/..")), root.join("a"));
    }

    #[test]
    fn outputs_around_inputs_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let survey = d.path().join("survey");
        let wc = survey.join("water");
        std::fs::create_dir_all(&wc).unwrap();
        std::fs::write(survey.join("IMG_0003.jpg"), b"x").unwrap();
        let inputs = [("survey", survey.as_path()), ("water column", wc.as_path())];
        let refused = [
            survey.clone(),
            survey.join("out"),
            survey.join("nonexistent/../"),
            d.path().join("nonexistent/../survey"),
            survey.join("IMG_0003.jpg"),
            d.path().to_path_buf(),
        ];
        for out in &refused {
            let e = check_outputs(&[("--out", out)], &inputs);
            assert!(e.is_err(), "{}", out.display());
        }
        let e = check_outputs(&[("--report", &survey.join("IMG_0003.jpg"))], &inputs)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--report") && e.contains("is the survey") || e.contains("inside"),
            "{e}"
        );
        let e = check_outputs(&[("--out", d.path())], &inputs)
            .unwrap_err()
            .to_string();
        assert!(e.contains("contains the survey"), "{e}");
        for ok in [
            d.path().join("out"),
            d.path().join("survey2"),
            d.path().join("x/../out"),
        ] {
            assert!(
                check_outputs(&[("--out", &ok)], &inputs).is_ok(),
                "{}",
                ok.display()
            );
        }
    }

    #[cfg(unix)]
    #[test]
    fn links_below_the_output_folder_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let elsewhere = d.path().join("elsewhere");
        std::fs::create_dir_all(out.join("real")).unwrap();
        std::fs::create_dir_all(&elsewhere).unwrap();
        std::os::unix::fs::symlink(&elsewhere, out.join("_abysslight")).unwrap();
        std::os::unix::fs::symlink(&elsewhere, out.join("real/sub")).unwrap();
        std::fs::write(out.join("file"), b"x").unwrap();
        assert!(check_no_links_below(&out, &out.join("real/a.jpg")).is_ok());
        assert!(check_no_links_below(&out, &out.join("new/deeper/a.jpg")).is_ok());
        let e = check_no_links_below(&out, &out.join("_abysslight/report.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("_abysslight") && e.contains("symbolic link"),
            "{e}"
        );
        assert!(check_no_links_below(&out, &out.join("real/sub/a.jpg")).is_err());
        assert!(check_no_links_below(&out, &out.join("file/a.jpg")).is_err());
        assert!(check_no_links_below(&out, &out.join("../x.jpg")).is_err());
        // The output folder itself may be a link the user chose.
        let link_out = d.path().join("link-out");
        std::os::unix::fs::symlink(&out, &link_out).unwrap();
        assert!(check_no_links_below(&link_out, &link_out.join("real/a.jpg")).is_ok());
    }
}
