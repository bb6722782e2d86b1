//! Benchmarks (criterion): batch OADEV at octave τ on 5.4 M samples (90 min at 1 kHz), and
//! the streaming engine's throughput on the host. docs/benchmarks.md records a run.
use allan::{deviation, DeviceEngine, Stat, TauSet};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

fn samples(n: usize) -> Vec<i32> {
    let mut s = 0x9e37_79b9u32;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s >> 21) as i32 - 1024
        })
        .collect()
}

fn batch(c: &mut Criterion) {
    let n = 5_400_000;
    let y: Vec<f64> = samples(n).into_iter().map(|v| v as f64 * 0.0076).collect();
    let mut g = c.benchmark_group("batch");
    g.sample_size(10);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_with_input(BenchmarkId::new("oadev_octave", n), &y, |b, y| {
        b.iter(|| deviation(y, 1e-3, Stat::Oadev, &TauSet::Octave).unwrap())
    });
    g.finish();
}

fn streaming(c: &mut Criterion) {
    let n = 1 << 20;
    let y = samples(n);
    let mut g = c.benchmark_group("streaming");
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("device_engine_push", |b| {
        b.iter(|| {
            let mut e = DeviceEngine::new();
            for &v in &y {
                e.push(v);
            }
            e.level(10).map(|l| l.sum2)
        })
    });
    g.finish();
}

criterion_group!(benches, batch, streaming);
criterion_main!(benches);
