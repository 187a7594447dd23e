// io/cad.h in the program: what needs no Open CASCADE (the checks, the trial read in a child,
// the snapping and repair of a tessellation, the atomic writes) is here; the rest goes through
// the CAD module's table (io/cad_module.h), opened on first use or by preload_cad_module.
#include "io/cad.h"

#include <dlfcn.h>
#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cctype>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <mutex>
#include <string_view>
#include <system_error>
#include <thread>
#include <unordered_map>

#include "io/cad_module.h"
#include "io/encode.h"
#include "io/read_file.h"
#include "io/write_mesh.h"

namespace flank::io {

namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& name, const std::string& problem) {
  throw Error(name + ": " + problem);
}

// The two builds of the module (io/CMakeLists.txt): STEP's, which every decompose and fit
// opens, and IGES's, the same code with IGES's translator too, opened for IGES files only.
// Both are built from one source and run on the same Open CASCADE libraries, so a surface one
// made can be written by the other (a surface fitted for patches.step, written as IGES).
struct ModuleBuild {
  const char* file;      // beside the running program
  const char* built_at;  // where the build put it
  const char* env;       // the variable that names it instead
  const char* needs;     // for the message when it does not open
};
constexpr ModuleBuild kStepModule{"libflank_cad.so", FLANK_CAD_MODULE_PATH, "FLANK_CAD_MODULE",
                                  "STEP files need flank's CAD module"};
constexpr ModuleBuild kIgesModule{"libflank_cad_iges.so", FLANK_CAD_IGES_MODULE_PATH, "FLANK_CAD_IGES_MODULE",
                                  "IGES files need flank's IGES module"};

// A module is opened once per process and never closed: the shapes and surfaces it made are
// freed by its own code whenever the last holder lets go, up to the process's exit. Where it
// is looked for, in order: its variable ($FLANK_CAD_MODULE, $FLANK_CAD_IGES_MODULE); beside
// the running program (the flank binary and the modules are built into one folder, and may be
// copied together); the path it was built at (the tests', benchmarks' and fuzzers' binaries
// live elsewhere).
class Module {
 public:
  static Module& step() {
    static Module module(kStepModule);
    return module;
  }
  static Module& iges() {
    static Module module(kIgesModule);
    return module;
  }
  // Starts opening the module on a thread of its own, once, unless it is open; the thread is
  // joined by the first get() or by settle().
  void preload() {
    const std::lock_guard lock(mutex_);
    if (started_ || ready_.load(std::memory_order_acquire)) return;
    started_ = true;
    try {
      thread_ = std::thread([this] { open(); });
    } catch (const std::system_error&) {
      // No thread to spare: the module is opened when first needed instead.
    }
  }
  // The table, or io::Error("NAME: problem") when the module cannot be opened.
  const cad_module::Api& get(const std::string& name) {
    if (const cad_module::Api* api = ready_.load(std::memory_order_acquire)) return *api;
    settle();
    open();
    if (!api_) fail(name, error_);
    ready_.store(api_, std::memory_order_release);
    return *api_;
  }
  bool ready() const { return ready_.load(std::memory_order_acquire) != nullptr; }
  void settle() {
    const std::lock_guard lock(mutex_);
    if (thread_.joinable()) thread_.join();
  }
  // Too late for the thread (settle_cad_module): exit has already run the destructors the
  // libraries it opens registered, while it may still be using them. Joined all the same, as
  // std::thread must be.
  ~Module() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  explicit Module(const ModuleBuild& build) : build_(build) {}
  void open() {
    std::call_once(once_, [this] {
      std::vector<std::string> paths;
      if (const char* env = std::getenv(build_.env); env && *env) {
        paths.emplace_back(env);
      } else {
        std::error_code ec;
        const fs::path self = fs::read_symlink("/proc/self/exe", ec);
        if (!ec) paths.push_back((self.parent_path() / build_.file).string());
        if (paths.empty() || paths.front() != build_.built_at) paths.emplace_back(build_.built_at);
      }
      std::string tried;
      for (const std::string& path : paths) {
        if (!tried.empty()) tried += "; ";
        void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
          const char* why = ::dlerror();
          tried += why ? one_line(why) : path + ": cannot open";
          continue;
        }
        using Entry = const cad_module::Api* (*)();
        const auto entry = reinterpret_cast<Entry>(::dlsym(handle, "flank_cad_module"));
        const cad_module::Api* api = entry ? entry() : nullptr;
        if (!api || api->version != cad_module::kVersion) {
          tried += path + ": not this flank's CAD module (rebuild flank)";
          continue;
        }
        api_ = api;
        break;
      }
      if (!api_)
        error_ = std::string(build_.needs) + " (" + build_.file + ", Open CASCADE), which did not open: " + tried;
    });
  }

  const ModuleBuild& build_;
  std::mutex mutex_;
  std::thread thread_;
  std::once_flag once_;
  bool started_ = false;  // under mutex_: preload started the thread once
  const cad_module::Api* api_ = nullptr;  // written once, in open()
  std::string error_;
  std::atomic<const cad_module::Api*> ready_{nullptr};
};

// Whether `name` ends in .igs or .iges, in any case (no allocation: a read part's face points
// and distances ask for their module at every call).
bool iges_name(std::string_view name) {
  const auto ends_with = [&](std::string_view ext) {
    return name.size() >= ext.size() &&
           std::equal(ext.begin(), ext.end(), name.end() - static_cast<std::ptrdiff_t>(ext.size()),
                      [](char e, char c) { return e == std::tolower(static_cast<unsigned char>(c)); });
  };
  return ends_with(".igs") || ends_with(".iges");
}

// The module for the file `name`: IGES's for an IGES file, else STEP's (also for the names of
// surfaces, which are not files). Open CASCADE's set-up is not thread-safe, and each module sets
// it up as it opens (the translators' controllers, a STEP writer's session): IGES's is opened
// only once STEP's, if it is opening beside, is done. (A decompose of an IGES part opened both
// at once and wrote a patches.step OCCT could not write, in 18 runs of 20.)
const cad_module::Api& module(const std::string& name) {
  if (!iges_name(name)) return Module::step().get(name);
  if (!Module::iges().ready()) Module::step().settle();
  return Module::iges().get(name);
}

}  // namespace

// Not once IGES's module is open: the command may be using Open CASCADE already (module()).
void preload_cad_module() {
  if (!Module::iges().ready()) Module::step().preload();
}
void settle_cad_module() { Module::step().settle(); }  // IGES's is never preloaded
void require_cad_module(const std::string& name) { module(name); }

bool is_cad_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  return cad_module::step_extension(ext) || ext == ".iges" || ext == ".igs";
}

struct CadPart::Impl {
  std::string path;
  std::string format;
  std::shared_ptr<const cad_module::Shape> shape;
  std::vector<CadFace> faces;
  std::vector<std::string> names;  // per face, "" when unnamed
};

CadPart::CadPart(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
CadPart::CadPart(CadPart&&) noexcept = default;
CadPart& CadPart::operator=(CadPart&&) noexcept = default;
CadPart::~CadPart() = default;

namespace {

enum class ChildEnd { finished, crashed, timed_out };

// Runs `work` in a child process: how it ended. The child's output goes to /dev/null and it
// dies by the default action of a fatal signal, whatever handlers (a sanitizer's, a fuzzer's)
// the parent installed; after `seconds` it is killed.
ChildEnd run_in_child(const std::function<void()>& work, double seconds) {
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) return ChildEnd::finished;  // no child to spare: read in this process as without the probe
  if (pid == 0) {
    // The child never outlives flank (killed, or interrupted with Ctrl-C).
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(1);
    for (const int sig : {SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) {
      ::dup2(null, STDOUT_FILENO);
      ::dup2(null, STDERR_FILENO);
    }
    try {
      work();
    } catch (...) {
      ::_exit(1);
    }
    ::_exit(0);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  int status = 0;
  for (;;) {
    const pid_t done = ::waitpid(pid, &status, WNOHANG);
    if (done == pid) return WIFSIGNALED(status) ? ChildEnd::crashed : ChildEnd::finished;
    if (done < 0 && errno != EINTR) return ChildEnd::finished;
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      return ChildEnd::timed_out;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

}  // namespace

// Open CASCADE's STEP and IGES translators dereference null handles on some malformed files
// (the fuzzer found a STEP whose cartesian point refers to nothing: a SEGV inside
// StepGeom_CartesianPoint). They are not flank's code to fix, and a crash must never be the
// answer to a bad file: the file is first read, and its faces coarsely tessellated, in a child
// process; only if that child survives is it read here. Reading twice costs the time of a read.
CadPart CadPart::read(const std::string& path, double probe_seconds) {
  // The same refusals as a mesh file (not regular, empty, too large) before OCCT sees it.
  const FileBytes bytes = read_regular_file(path, kMaxCadFileBytes);
  // The module is opened before the fork: the child then has it, and no half-opened copy.
  module(path);
  // OCCT's readers trust counts in the file (an IGES edge list of a billion edges from a 6 KB
  // file), so the probe also has a time limit: by default a minute plus 10 s per MB.
  if (!(probe_seconds > 0)) probe_seconds = 60.0 + 10.0 * static_cast<double>(bytes.size()) / (1 << 20);
  const ChildEnd end = run_in_child([&] {
    const CadPart probe(read_in_process(path));
    const BoundingBox box = probe.bounding_box({});
    if (box.diagonal() > 0 && std::isfinite(box.diagonal())) probe.tessellate({}, 1e-2 * box.diagonal(), {}, false);
  }, probe_seconds);
  if (end == ChildEnd::crashed)
    fail(path, "Open CASCADE crashed reading this file: it is malformed, or holds entities OCCT cannot read");
  if (end == ChildEnd::timed_out)
    fail(path, "Open CASCADE did not finish reading this file in " + std::to_string(std::lround(probe_seconds)) +
                   " s: it is malformed (counts far beyond its size), or too large to read");
  return CadPart(read_in_process(path));
}

std::unique_ptr<CadPart::Impl> CadPart::read_in_process(const std::string& path) {
  const FileBytes file = read_regular_file(path, kMaxCadFileBytes);
  const std::string_view bytes = file;
  if (bytes.empty()) fail(path, "empty file");
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  const std::string ext = lower_extension(path);
  const bool step = cad_module::step_extension(ext);
  impl->format = step ? "step" : "iges";
  if (step && bytes.find("ISO-10303-21") == std::string_view::npos)
    fail(path, "not a STEP file (no ISO-10303-21 header)");
  impl->shape = module(path).read(path, step, impl->faces, impl->names);
  return impl;
}

const std::string& CadPart::format() const { return impl_->format; }
const std::vector<CadFace>& CadPart::faces() const { return impl_->faces; }

void CadPart::check_faces(const std::vector<int>& faces) const {
  const int n = static_cast<int>(impl_->faces.size());
  for (const int f : faces)
    if (f < 1 || f > n)
      fail(impl_->path, "--faces: face " + std::to_string(f) + " does not exist (the file has faces 1.." +
                            std::to_string(n) + ")");
}

BoundingBox CadPart::bounding_box(const std::vector<int>& faces) const {
  check_faces(faces);
  BoundingBox box;
  bool first = true;
  for (const CadFace& f : impl_->faces) {
    if (!faces.empty() && std::find(faces.begin(), faces.end(), f.index) == faces.end()) continue;
    box.min = first ? f.min : Vec3(box.min.cwiseMin(f.min));
    box.max = first ? f.max : Vec3(box.max.cwiseMax(f.max));
    first = false;
  }
  return box;
}

CadTessellation CadPart::tessellate(const std::vector<int>& faces, double deviation,
                                    const ReadOptions& options) const {
  return tessellate(faces, deviation, options, true);
}

CadTessellation CadPart::tessellate(const std::vector<int>& faces, double deviation, const ReadOptions& options,
                                    bool parallel) const {
  check_faces(faces);
  const std::string& path = impl_->path;
  if (!(deviation > 0) || !std::isfinite(deviation)) fail(path, "the chord deviation must be a positive length");
  std::vector<int> chosen = faces;
  if (chosen.empty())
    for (const CadFace& f : impl_->faces) chosen.push_back(f.index);
  std::sort(chosen.begin(), chosen.end());
  chosen.erase(std::unique(chosen.begin(), chosen.end()), chosen.end());
  const double diagonal = bounding_box(chosen).diagonal();

  CadTessellation out;
  out.faces = static_cast<int>(chosen.size());
  std::vector<double> xyz;
  std::vector<int> triangles;
  // Sewn first, so that faces meeting along an edge share its points.
  module(path).tessellate(*impl_->shape, path, chosen, std::max(1e-6 * diagonal, 1e-7), deviation, parallel, xyz,
                          triangles, out.deviation);
  if (triangles.empty()) fail(path, "the chosen faces gave no triangles");

  // Points of an edge shared by two faces may differ by rounding: snap each point onto the
  // first one within 1e-7 of the diagonal, so that the mesh repair welds them.
  const double snap = std::max(1e-7 * diagonal, 1e-12);
  struct Key {
    long long x, y, z;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      return std::hash<long long>()(k.x * 73856093LL ^ k.y * 19349663LL ^ k.z * 83492791LL);
    }
  };
  std::unordered_map<Key, std::vector<int>, KeyHash> cells;
  const std::size_t nv = xyz.size() / 3;
  for (std::size_t v = 0; v < nv; ++v) {
    const Key key{std::llround(xyz[3 * v] / snap), std::llround(xyz[3 * v + 1] / snap),
                  std::llround(xyz[3 * v + 2] / snap)};
    int found = -1;
    for (long long dx = -1; dx <= 1 && found < 0; ++dx)
      for (long long dy = -1; dy <= 1 && found < 0; ++dy)
        for (long long dz = -1; dz <= 1 && found < 0; ++dz) {
          const auto it = cells.find({key.x + dx, key.y + dy, key.z + dz});
          if (it == cells.end()) continue;
          for (const int u : it->second) {
            const double d = std::hypot(xyz[3 * v] - xyz[3 * u], xyz[3 * v + 1] - xyz[3 * u + 1],
                                        xyz[3 * v + 2] - xyz[3 * u + 2]);
            if (d <= snap) {
              found = u;
              break;
            }
          }
        }
    if (found >= 0) {
      for (int c = 0; c < 3; ++c) xyz[3 * v + c] = xyz[3 * static_cast<std::size_t>(found) + c];
    } else {
      cells[key].push_back(static_cast<int>(v));
    }
  }
  out.mesh = repair_triangles(path, std::move(xyz), std::move(triangles), impl_->format, options);
  return out;
}

Vec3 CadPart::face_point(int index, double u, double v) const {
  check_faces({index});
  return module(impl_->path).face_point(*impl_->shape, impl_->path, index, u, v);
}

double CadPart::distance(const Vec3& p) const {
  return module(impl_->path).distance(*impl_->shape, impl_->path, p);
}

std::string CadPart::face_name(int index) const {
  check_faces({index});
  return impl_->names[static_cast<std::size_t>(index - 1)];
}

// ---------------------------------------------------------------------------------------
// Writing

struct SplineSurface::Impl {
  const cad_module::Api* api = nullptr;  // the module that made it
  std::shared_ptr<const cad_module::Surface> surface;
  int poles_u = 0, poles_v = 0, degree_u = 0, degree_v = 0;
};

// The program's side of a surface the module made: its handle, and its size asked once.
struct CadWriter {
  static SplineSurface make(const std::string& name, std::shared_ptr<const cad_module::Surface> surface) {
    auto impl = std::make_shared<SplineSurface::Impl>();
    impl->api = &module(name);
    impl->api->size(*surface, impl->poles_u, impl->poles_v, impl->degree_u, impl->degree_v);
    impl->surface = std::move(surface);
    return SplineSurface(std::move(impl));
  }
  static const cad_module::Surface* surface(const SplineSurface& s) { return s.impl_->surface.get(); }
};

SplineSurface::SplineSurface(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
SplineSurface::SplineSurface(const SplineSurface&) = default;
SplineSurface& SplineSurface::operator=(const SplineSurface&) = default;
SplineSurface::~SplineSurface() = default;

SplineSurface SplineSurface::fit(const std::string& name, const Points& grid, int rows, int cols,
                                 double tolerance) {
  return CadWriter::make(name, module(name).fit(name, grid, rows, cols, tolerance));
}

SplineSurface SplineSurface::from_poles(const std::string& name, const Points& poles, int nu, int nv,
                                        const std::vector<double>& knots_u, const std::vector<double>& knots_v) {
  return CadWriter::make(name, module(name).from_poles(name, poles, nu, nv, knots_u, knots_v));
}

Vec3 SplineSurface::point(double u, double v) const { return impl_->api->point(*impl_->surface, u, v); }
int SplineSurface::poles_u() const { return impl_->poles_u; }
int SplineSurface::poles_v() const { return impl_->poles_v; }
int SplineSurface::degree_u() const { return impl_->degree_u; }
int SplineSurface::degree_v() const { return impl_->degree_v; }

namespace {

// Whether `path` names a STEP file (else IGES); io::Error for any other extension.
bool step_path(const fs::path& path) {
  const std::string ext = lower_extension(path);
  const bool step = cad_module::step_extension(ext);
  if (!step && ext != ".iges" && ext != ".igs")
    fail(path.string(), "unsupported CAD extension '" + one_line(ext) + "' (expected .step, .stp, .iges or .igs)");
  return step;
}

// A run that found no patch still replaces the earlier run's file: a STEP file with an empty
// data section (OCCT writes no file without a shape), written without opening the module.
// IGES has no such file.
void write_empty(const fs::path& path, bool step) {
  if (!step) fail(path.string(), "nothing to write");
  write_file_atomic(path, [&](std::ostream& out) {
    out << "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('flank: no shapes'),'2;1');\nFILE_NAME('"
        << one_line(path.filename().string())
        << "','1970-01-01T00:00:00',(''),(''),'flank','flank','');\n"
           "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\nDATA;\nENDSEC;\n"
           "END-ISO-10303-21;\n";
  });
}

}  // namespace

void write_surfaces(const fs::path& path, const std::vector<NamedSurface>& surfaces) {
  const bool step = step_path(path);
  if (surfaces.empty()) return write_empty(path, step);
  std::vector<std::pair<std::string, const cad_module::Surface*>> named;
  for (const NamedSurface& s : surfaces) named.emplace_back(s.name, CadWriter::surface(s.surface));
  write_file_atomic(path, module(path.string()).surfaces_file(path.string(), named));
}

void write_solids(const fs::path& path, const std::vector<RevolvedSolid>& solids) {
  const bool step = step_path(path);
  if (solids.empty()) return write_empty(path, step);
  write_file_atomic(path, module(path.string()).solids_file(path.string(), solids));
}

}  // namespace flank::io
