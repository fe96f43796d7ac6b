// The converter's threads under a sanitizer (make test-tsan, make test-asan): converts a
// dataset with media several times with several worker threads, cancels conversions from
// another thread at every stage, and checks that the uncancelled runs agree.
//
//   bsp_convert_threads DATASET_DIR OUT_DIR [threads]
//
// DATASET_DIR is a bsp-synth dataset (Makefile: a small one in the build directory).
// Exit 0 when every run behaved, 1 otherwise (the sanitizer exits on its own findings).
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "bsp/common/errors.hpp"
#include "bsp/conversion/convert.hpp"

namespace {

bsp::ConvertOptions options(const std::string& dataset, int threads) {
  bsp::ConvertOptions opt;
  opt.threads = threads;
  opt.verify = true;
  opt.clips.length = 8;
  opt.media.crop_size = 32;
  opt.source_path = dataset;
  return opt;
}

int fail(const std::string& what) {
  std::fprintf(stderr, "bsp_convert_threads: %s\n", what.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return fail("usage: bsp_convert_threads DATASET_DIR OUT_DIR [threads]");
  const std::string dataset = argv[1], out = argv[2];
  const int threads = argc > 3 ? std::stoi(argv[3]) : 3;
  const std::string csv = dataset + "/data.csv";
  std::filesystem::create_directories(out);

  // Two complete runs: the same clips and frames whatever the scheduling.
  bsp::ConvertReport first;
  for (int run = 0; run < 2; ++run) {
    const std::string path = out + "/full" + std::to_string(run) + ".h5";
    bsp::ConvertProgress progress;
    const bsp::ConvertReport r = bsp::convert_csv(csv, path, options(dataset, threads), &progress);
    const std::size_t frames = r.media.frames[0] + r.media.frames[1] + r.media.frames[2];
    std::printf("run %d: %zu rows, %zu recordings, %zu clips, %zu media frames\n", run, r.rows,
                r.recordings, r.clips[0] + r.clips[1] + r.clips[2], frames);
    if (frames == 0) return fail("no media frames were written");
    if (run == 0) first = r;
    else if (r.clips != first.clips || r.media.frames != first.media.frames)
      return fail("two runs of the same conversion disagree");
  }

  // One clip per HDF5 chunk and --compress: the pose arrays are written in many batches,
  // each filled and its chunks packed by the workers while the previous one is written.
  {
    bsp::ConvertOptions o = options(dataset, threads);
    o.chunk_clips = 1;
    o.compress = true;
    bsp::ConvertProgress progress;
    const bsp::ConvertReport r = bsp::convert_csv(csv, out + "/packed.h5", o, &progress);
    if (r.clips != first.clips) return fail("the packed conversion planned other clips");
    std::printf("packed run: %zu clips in one-clip compressed chunks\n",
                r.clips[0] + r.clips[1] + r.clips[2]);
  }

  // Without media and --verify the pose columns are deferred (issue 59): the fill threads
  // parse them from the file while the calling thread writes, several threads reading the
  // one file at once. Same clips as with media.
  {
    bsp::ConvertOptions o = options(dataset, threads);
    o.media.enabled = false;
    o.verify = false;
    bsp::ConvertProgress progress;
    const bsp::ConvertReport r = bsp::convert_csv(csv, out + "/deferred.h5", o, &progress);
    if (r.clips != first.clips) return fail("the deferred conversion planned other clips");
    std::printf("deferred run: %zu clips\n", r.clips[0] + r.clips[1] + r.clips[2]);
  }

  // Cancelled runs: another thread sets `cancel` once the conversion reaches `stage`
  // (read, check_media, media, ...); convert_csv must join its workers and
  // throw "conversion cancelled" (or finish, when the stage came and went too fast).
  int cancelled = 0;
  using S = bsp::ConvertStage;
  for (S stage : {S::read, S::plan, S::write, S::check_media, S::media}) {
    bsp::ConvertProgress progress;
    std::atomic<bool> done{false};
    std::thread canceller([&] {
      while (!done.load() && progress.stage.load() < stage)
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      progress.cancel.store(true);
    });
    const std::string path = out + "/cancel" + std::to_string(static_cast<int>(stage)) + ".h5";
    try {
      bsp::convert_csv(csv, path, options(dataset, threads), &progress);
    } catch (const bsp::Error& e) {
      if (std::string(e.what()).find("conversion cancelled") == std::string::npos) {
        done = true;
        canceller.join();
        return fail(std::string("unexpected error: ") + e.what());
      }
      ++cancelled;
    }
    done = true;
    canceller.join();
  }
  std::printf("%d of 5 conversions cancelled cleanly\n", cancelled);
  if (cancelled == 0) return fail("no conversion could be cancelled");
  return 0;
}
