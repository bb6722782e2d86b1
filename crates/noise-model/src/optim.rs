//! One-dimensional minimisation shared by the fit, the time-domain tests and the spectral
//! band search.

/// Minimise `f` on [a, b] by golden-section search (at most `iterations` steps, or until the
/// bracket is 1e-7 of its position): (argmin, min).
pub fn golden_min(
    mut f: impl FnMut(f64) -> f64,
    mut a: f64,
    mut b: f64,
    iterations: usize,
) -> (f64, f64) {
    let r = 0.618_033_988_749_895;
    let mut x1 = b - r * (b - a);
    let mut x2 = a + r * (b - a);
    let mut f1 = f(x1);
    let mut f2 = f(x2);
    for _ in 0..iterations {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - r * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + r * (b - a);
            f2 = f(x2);
        }
        if (b - a).abs() <= 1e-7 * (a.abs() + b.abs()).max(1e-300) {
            break;
        }
    }
    if f1 < f2 {
        (x1, f1)
    } else {
        (x2, f2)
    }
}
