//! Panics become errors: [`catch`] runs a closure and turns a panic inside it (on its
//! thread or on a rayon worker it waits for) into a message with the panic's source
//! location. While any `catch` is active the panic hook records instead of printing,
//! so the user sees one clean error, not a Rust backtrace note; outside a `catch` the
//! default hook prints as usual.

use std::any::Any;
use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, Once};

static CATCHING: AtomicUsize = AtomicUsize::new(0);
/// (message, location) of panics seen while catching, newest last.
static SEEN: Mutex<Vec<(String, String)>> = Mutex::new(Vec::new());
static HOOK: Once = Once::new();

/// Runs `f`; a panic inside it becomes `Err("MESSAGE (at FILE:LINE:COLUMN)")`.
pub fn catch<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    HOOK.call_once(install_hook);
    CATCHING.fetch_add(1, Ordering::SeqCst);
    let result = panic::catch_unwind(AssertUnwindSafe(f));
    CATCHING.fetch_sub(1, Ordering::SeqCst);
    result.map_err(|payload| describe(payload.as_ref()))
}

fn install_hook() {
    let default = panic::take_hook();
    panic::set_hook(Box::new(move |info| {
        if CATCHING.load(Ordering::SeqCst) == 0 {
            return default(info);
        }
        let location = info.location().map(|l| format!("{}:{}:{}", l.file(), l.line(), l.column())).unwrap_or_default();
        if let Ok(mut seen) = SEEN.lock() {
            seen.push((message(info.payload()), location));
        }
    }));
}

fn describe(payload: &(dyn Any + Send)) -> String {
    let message = message(payload);
    let location = SEEN.lock().ok().and_then(|mut seen| {
        let at = seen.iter().rposition(|(m, _)| *m == message)?;
        Some(seen.remove(at).1)
    });
    match location {
        Some(location) if !location.is_empty() => format!("{message} (at {location})"),
        _ => message,
    }
}

fn message(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn a_panic_becomes_its_message_and_location() {
        let err = catch(|| -> u32 { panic!("bad size {}", 7) }).unwrap_err();
        assert!(err.starts_with("bad size 7 (at pipeline/src/panic.rs:"), "{err}");
        assert_eq!(catch(|| 3).unwrap(), 3);
    }

    #[test]
    fn a_panic_on_a_rayon_worker_is_caught_by_the_caller() {
        let err =
            catch(|| (0..64).into_par_iter().map(|i| if i == 40 { panic!("worker {i}") } else { i }).sum::<i32>())
                .unwrap_err();
        assert!(err.starts_with("worker 40"), "{err}");
    }
}
