// bench_bus_auth (Google Benchmark): the cost of the bus envelope (common/bus_auth.h) on one
// feature frame of 2000 features (16,168 bytes, the default budget): seal on the sender plus
// open on the receiver, for an open bus, an authenticated one and an encrypted one. Compare
// with the frame's round-trip latency (docs/RESULTS.md).
#include <benchmark/benchmark.h>

#include "m2s/common/bus_auth.h"

namespace m2s::wire {
namespace {

constexpr size_t kFeatures = 2000;

void BM_SealAndOpenFrame(benchmark::State& state) {
  const int mode = static_cast<int>(state.range(0));  // 0 open, 1 authenticated, 2 encrypted
  std::optional<BusKey> key;
  if (mode > 0) {
    const std::vector<uint8_t> secret(32, 0x42);
    key = *BusKeyFromBytes(secret.data(), secret.size());
  }
  BusSealer sealer(key, mode == 2, 1234);
  BusOpenerOptions options;
  options.max_age_s = 0;  // the benchmark's clock is fixed
  BusOpener opener(key, options);
  std::vector<uint8_t> frame(FeatureFrameEncodedSize(kFeatures));
  for (size_t i = 0; i < frame.size(); ++i) frame[i] = static_cast<uint8_t>(i * 31);
  for (auto _ : state) {
    const std::vector<uint8_t> sealed = sealer.Seal(kFrameChannel, frame.data(), frame.size(), 0);
    auto opened = opener.Open(kFrameChannel, sealed.data(), sealed.size(), 0);
    benchmark::DoNotOptimize(opened.ok());
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * frame.size()));
  state.SetLabel(mode == 0 ? "open bus" : mode == 1 ? "authenticated" : "encrypted");
}
BENCHMARK(BM_SealAndOpenFrame)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace m2s::wire
