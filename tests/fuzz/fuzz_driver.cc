// The fuzz targets' main() when libFuzzer is not there (a GCC build, or Clang without
// ARBOR_FUZZ): runs every input of the corpus directories and files named on the command line,
// then `-runs` inputs made from them by seeded mutations (bit flips, bytes set to edge values,
// bytes inserted, erased, repeated or spliced from another input, the input cut short), each
// through the target's LLVMFuzzerTestOneInput. Not coverage-guided: it keeps a fuzz target
// exercised in every build. It takes libFuzzer's flags that matter here (-runs, -seed,
// -max_total_time, -max_len, -timeout, -artifact_prefix) and ignores the others, so a test runs
// either with the same command line.
//
// An input that crashes the target (a signal, or a sanitizer's report when one is built in) or
// runs past -timeout seconds is written to <artifact_prefix>crash-<seed>-<run> (or timeout-…)
// before the process dies; `TARGET FILE` runs that file alone.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

// With AddressSanitizer built in (ARBOR_SANITIZE), its report ends the process without a signal:
// a death callback writes the input out then.
#if defined(__SANITIZE_ADDRESS__)
#define ARBOR_HAVE_SANITIZER_INTERFACE 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ARBOR_HAVE_SANITIZER_INTERFACE 1
#endif
#endif
#ifdef ARBOR_HAVE_SANITIZER_INTERFACE
#include <sanitizer/common_interface_defs.h>
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

using Bytes = std::vector<std::uint8_t>;

// What a crash handler writes out (set before each run; signal handlers read it).
const std::uint8_t* g_current = nullptr;
std::size_t g_current_size = 0;
char g_crash_path[4096] = "";
char g_timeout_path[4096] = "";

void writeCurrent(const char* path) {
  if (g_current == nullptr || path[0] == '\0') return;
  const int fd = ::open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) return;
  std::size_t done = 0;
  while (done < g_current_size) {
    const ssize_t n = ::write(fd, g_current + done, g_current_size - done);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
  const char note[] = "fuzz driver: the input is in ";
  (void)!::write(2, note, sizeof(note) - 1);
  (void)!::write(2, path, std::strlen(path));
  (void)!::write(2, "\n", 1);
}

void onCrash(int sig) {
  writeCurrent(g_crash_path);
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

void onTimeout(int) {
  const char note[] = "fuzz driver: an input ran past -timeout\n";
  (void)!::write(2, note, sizeof(note) - 1);
  writeCurrent(g_timeout_path);
  ::_exit(70);
}

#ifdef ARBOR_HAVE_SANITIZER_INTERFACE
void onSanitizerDeath() { writeCurrent(g_crash_path); }
#endif

Bytes readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Values at the edges of integer fields (big- and little-endian alike when symmetric).
const std::uint32_t kEdgeValues[] = {0,          1,          2,          0x7F,       0x80,
                                     0xFF,       0x100,      0x7FFF,     0x8000,     0xFFFF,
                                     0x7FFFFFFF, 0x80000000, 0xFFFFFF00, 0xFFFFFFFE, 0xFFFFFFFF};
// Text that the line readers meet (g2o/TORO): numbers at the edges of double, separators.
const char* const kTokens[] = {" ",
                               "\n",
                               "-",
                               "nan",
                               "inf",
                               "1e308",
                               "-1e308",
                               "0",
                               "-1",
                               "1e-320",
                               "9223372036854775807",
                               "#",
                               "FIX",
                               "0x10",
                               "1e400",
                               "EDGE2",
                               "VERTEX_SE3:QUAT"};

class Mutator {
 public:
  Mutator(std::uint64_t seed, std::size_t max_len) : rng_(seed), max_len_(max_len) {}

  std::size_t below(std::size_t n) { return n == 0 ? 0 : rng_() % n; }

  Bytes mutate(Bytes d, const std::vector<Bytes>& pool) {
    const std::size_t steps = 1 + below(6);
    for (std::size_t s = 0; s < steps; ++s) step(d, pool);
    if (d.size() > max_len_) d.resize(max_len_);
    return d;
  }

 private:
  void step(Bytes& d, const std::vector<Bytes>& pool) {
    switch (below(10)) {
      case 0:  // a bit flipped
        if (!d.empty()) d[below(d.size())] ^= static_cast<std::uint8_t>(1u << below(8));
        break;
      case 1:  // a byte set at random
        if (!d.empty()) d[below(d.size())] = static_cast<std::uint8_t>(rng_());
        break;
      case 2: {  // 1, 2 or 4 bytes set to an edge value, either byte order
        if (d.empty()) break;
        const std::uint32_t v = kEdgeValues[below(std::size(kEdgeValues))];
        const std::size_t width = std::size_t{1} << below(3);
        const std::size_t at = below(d.size());
        const bool big = below(2) == 0;
        for (std::size_t k = 0; k < width && at + k < d.size(); ++k) {
          const std::size_t shift = 8 * (big ? width - 1 - k : k);
          d[at + k] = static_cast<std::uint8_t>(v >> shift);
        }
        break;
      }
      case 3: {  // random bytes inserted
        const std::size_t at = below(d.size() + 1);
        const std::size_t n = 1 + below(16);
        Bytes ins(n);
        for (auto& b : ins) b = static_cast<std::uint8_t>(rng_());
        d.insert(d.begin() + static_cast<std::ptrdiff_t>(at), ins.begin(), ins.end());
        break;
      }
      case 4: {  // a range erased
        if (d.empty()) break;
        const std::size_t at = below(d.size());
        const std::size_t n = 1 + below(std::min<std::size_t>(d.size() - at, 64));
        d.erase(d.begin() + static_cast<std::ptrdiff_t>(at),
                d.begin() + static_cast<std::ptrdiff_t>(at + n));
        break;
      }
      case 5: {  // a range repeated
        if (d.empty()) break;
        const std::size_t at = below(d.size());
        const std::size_t n = 1 + below(std::min<std::size_t>(d.size() - at, 256));
        const Bytes copy(d.begin() + static_cast<std::ptrdiff_t>(at),
                         d.begin() + static_cast<std::ptrdiff_t>(at + n));
        const std::size_t to = below(d.size() + 1);
        d.insert(d.begin() + static_cast<std::ptrdiff_t>(to), copy.begin(), copy.end());
        break;
      }
      case 6:  // cut short
        d.resize(below(d.size() + 1));
        break;
      case 7: {  // spliced: the head of this input, the tail of another
        if (pool.empty()) break;
        const Bytes& other = pool[below(pool.size())];
        const std::size_t keep = below(d.size() + 1);
        const std::size_t from = below(other.size() + 1);
        d.resize(keep);
        d.insert(d.end(), other.begin() + static_cast<std::ptrdiff_t>(from), other.end());
        break;
      }
      case 8: {  // a token of text inserted (or put over a byte)
        const char* t = kTokens[below(std::size(kTokens))];
        const std::size_t at = below(d.size() + 1);
        if (below(2) == 0 && at < d.size()) d.erase(d.begin() + static_cast<std::ptrdiff_t>(at));
        d.insert(d.begin() + static_cast<std::ptrdiff_t>(at), t, t + std::strlen(t));
        break;
      }
      default:  // a byte plus or minus a little (lengths and counts off by a few)
        if (!d.empty()) {
          const std::size_t at = below(d.size());
          d[at] = static_cast<std::uint8_t>(d[at] + static_cast<int>(below(9)) - 4);
        }
        break;
    }
  }

  std::mt19937_64 rng_;
  std::size_t max_len_;
};

bool flag(const char* arg, const char* name, long long* value) {
  const std::size_t n = std::strlen(name);
  if (std::strncmp(arg, name, n) != 0 || arg[n] != '=') return false;
  *value = std::atoll(arg + n + 1);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  long long runs = 10000, seed = 1, max_total_time = 0, max_len = 0, timeout = 60, v = 0;
  std::string artifact_prefix = "./";
  std::vector<std::string> inputs;
  for (int k = 1; k < argc; ++k) {
    const char* a = argv[k];
    if (flag(a, "-runs", &v)) {
      runs = v;
    } else if (flag(a, "-seed", &v)) {
      seed = v;
    } else if (flag(a, "-max_total_time", &v)) {
      max_total_time = v;
    } else if (flag(a, "-max_len", &v)) {
      max_len = v;
    } else if (flag(a, "-timeout", &v)) {
      timeout = v;
    } else if (std::strncmp(a, "-artifact_prefix=", 17) == 0) {
      artifact_prefix = a + 17;
    } else if (a[0] == '-') {
      std::fprintf(stderr, "fuzz driver: ignoring libFuzzer's %s\n", a);
    } else {
      inputs.push_back(a);
    }
  }
  std::snprintf(g_crash_path, sizeof g_crash_path, "%scrash-%lld", artifact_prefix.c_str(), seed);
  std::snprintf(g_timeout_path, sizeof g_timeout_path, "%stimeout-%lld", artifact_prefix.c_str(),
                seed);
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) ::signal(sig, onCrash);
  ::signal(SIGALRM, onTimeout);
#ifdef ARBOR_HAVE_SANITIZER_INTERFACE
  __sanitizer_set_death_callback(onSanitizerDeath);
#endif

  std::vector<Bytes> pool;
  for (const std::string& name : inputs) {
    std::error_code ec;
    if (std::filesystem::is_directory(name, ec)) {
      std::vector<std::filesystem::path> files;
      for (const auto& e : std::filesystem::directory_iterator(name)) {
        if (e.is_regular_file()) files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
      for (const auto& f : files) pool.push_back(readFile(f));
    } else if (std::filesystem::is_regular_file(name, ec)) {
      pool.push_back(readFile(name));
    } else {
      std::fprintf(stderr, "fuzz driver: %s is neither a file nor a directory\n", name.c_str());
      return 2;
    }
  }
  std::size_t longest = 0;
  for (const Bytes& d : pool) longest = std::max(longest, d.size());
  if (max_len <= 0) max_len = static_cast<long long>(std::max<std::size_t>(4096, 2 * longest));

  const auto run = [&](const Bytes& d) {
    g_current = d.data();
    g_current_size = d.size();
    ::alarm(static_cast<unsigned>(std::max(timeout, 1LL)));
    LLVMFuzzerTestOneInput(d.data(), d.size());
    ::alarm(0);
  };
  const auto start = std::chrono::steady_clock::now();
  long long done = 0;
  for (const Bytes& d : pool) {
    run(d);
    ++done;
  }
  if (pool.empty()) pool.push_back(Bytes{});
  Mutator mutator(static_cast<std::uint64_t>(seed), static_cast<std::size_t>(max_len));
  long long mutated = 0;
  std::size_t cursor = 0;
  Bytes last;
  for (; mutated < runs; ++mutated) {
    if (max_total_time > 0 && mutated % 256 == 0 &&
        std::chrono::steady_clock::now() - start > std::chrono::seconds(max_total_time)) {
      break;
    }
    std::snprintf(g_crash_path, sizeof g_crash_path, "%scrash-%lld-%lld", artifact_prefix.c_str(),
                  seed, mutated);
    // Mostly a corpus input; sometimes the last mutant again (mutations that build on each other).
    const Bytes& base =
        (!last.empty() && mutator.below(4) == 0) ? last : pool[cursor++ % pool.size()];
    last = mutator.mutate(base, pool);
    run(last);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "fuzz driver: %lld corpus inputs and %lld mutated inputs (seed %lld) in %.1f s, no crash\n",
      done, mutated, seed, seconds);
  std::printf("stat::number_of_executed_units: %lld\n", done + mutated);
  return 0;
}
