//! Times forward + backward of the two networks on random batches (no rendering).
use candle_core::{Device, Tensor};
use gpmm_core::net::Shape;
use gpmm_train::nets::{finder_specs, initializer_specs, Net};

fn main() -> candle_core::Result<()> {
    let device = Device::Cpu;
    let b = 64;
    for (name, side, net) in [
        ("finder", 96, Net::new(Shape { h: 96, w: 96, c: 3 }, finder_specs(), 1, &device)?),
        ("initializer", 64, Net::new(Shape { h: 64, w: 64, c: 3 }, initializer_specs(151), 2, &device)?),
    ] {
        let x = Tensor::randn(0f32, 1.0, (b, side, side, 3), &device)?;
        for _ in 0..2 {
            let (y, _) = net.forward(&x)?;
            y.sqr()?.mean_all()?.backward()?;
        }
        let t = std::time::Instant::now();
        let n = 5;
        let mut fwd = 0.0;
        for _ in 0..n {
            let t0 = std::time::Instant::now();
            let (y, _) = net.forward(&x)?;
            let l = y.sqr()?.mean_all()?;
            fwd += t0.elapsed().as_secs_f64();
            l.backward()?;
        }
        let total = t.elapsed().as_secs_f64() / n as f64;
        println!(
            "{name}: {:.1} ms/step at batch {b} ({:.2} ms/sample), forward {:.1} ms",
            total * 1e3,
            total * 1e3 / b as f64,
            fwd / n as f64 * 1e3
        );
    }
    Ok(())
}
