// The Python module `tprf` (docs/python.md): the library's entry points for
// scenes, estimates, renders and sensors, with numpy arrays that share the result's memory.
//
// Every long call runs on a thread of its own with the GIL released; the calling thread hands the
// progress events to the Python callback in order and checks for Ctrl-C, which cancels the work
// through tprf::request_cancel (the flag every stage checks) and is raised as KeyboardInterrupt once
// the work has stopped.

#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/pipeline/info.h"
#include "tprf/imaging/ground_truth.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <deque>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>

namespace py = pybind11;

namespace {

/// tprf.Scene: a loaded, validated scene.
struct PyScene {
    std::shared_ptr<const tprf::Scene> scene;
};

/// tprf.Result: what a render computed; its arrays share this memory.
struct PyResult {
    std::shared_ptr<const tprf::RenderResult> result;
};

// The cancellation flag is process-wide: two long calls at once would cancel each other's Ctrl-C
// wrongly, and clear each other's request. One at a time, then; a call made from inside another's
// progress callback (the same thread) is refused, since it would wait for itself.
std::mutex g_one_call;
std::atomic<std::thread::id> g_caller{};

// Takes g_one_call, waiting in steps of 50 ms with the GIL released and checking for Ctrl-C between.
std::unique_lock<std::mutex> one_call_at_a_time() {
    if (g_caller.load() == std::this_thread::get_id())
        throw std::runtime_error("tprf: a tprf call from inside a progress callback of another (calls cannot nest)");
    std::unique_lock<std::mutex> lock(g_one_call, std::defer_lock);
    while (!lock.try_lock()) {
        {
            py::gil_scoped_release nogil;
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    }
    g_caller.store(std::this_thread::get_id());
    return lock;
}

// Whatever leaves run_cancellable while its worker runs (an exception of Python's or of ours) first
// stops the worker and waits for it: a joinable std::thread must not be destroyed.
struct StopAndJoin {
    std::thread& worker;
    ~StopAndJoin() {
        if (worker.joinable()) {
            tprf::request_cancel(SIGINT);
            py::gil_scoped_release nogil;
            worker.join();
        }
        tprf::clear_cancel();
        g_caller.store(std::thread::id());
    }
};

// Runs `work(progress)` on a thread of its own (see the top of this file). Returns its value or
// rethrows its exception; a KeyboardInterrupt or an exception of the callback wins over the work's
// own Cancelled.
template <class Work>
auto run_cancellable(Work work, const py::object& callback) -> decltype(work(tprf::ProgressFn{})) {
    using T = decltype(work(tprf::ProgressFn{}));
    const std::unique_lock<std::mutex> one = one_call_at_a_time();
    std::mutex m;
    std::condition_variable cv;
    bool done = false;
    std::deque<std::pair<std::string, double>> events;
    tprf::ProgressFn progress;
    if (!callback.is_none())
        progress = [&](std::string_view phase, double fraction) {
            const std::lock_guard<std::mutex> lock(m);
            events.emplace_back(std::string(phase), fraction);
            cv.notify_one();
        };
    std::optional<T> value;
    std::exception_ptr failure;
    tprf::clear_cancel();
    std::thread worker;
    const StopAndJoin guard{worker};  // also when the thread cannot be started
    worker = std::thread([&] {
        try {
            value.emplace(work(progress));
        } catch (...) {
            failure = std::current_exception();
        }
        const std::lock_guard<std::mutex> lock(m);
        done = true;
        cv.notify_one();
    });
    std::optional<py::error_already_set> interrupt;
    for (bool finished = false; !finished;) {
        std::deque<std::pair<std::string, double>> batch;
        {
            py::gil_scoped_release nogil;
            std::unique_lock<std::mutex> lock(m);
            cv.wait_for(lock, std::chrono::milliseconds(50), [&] { return done || !events.empty(); });
            batch.swap(events);
            finished = done;
        }
        if (interrupt) continue;  // cancelled: waiting for the work to stop
        try {
            for (const auto& [phase, fraction] : batch) callback(phase, fraction);
            if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        } catch (py::error_already_set& e) {
            interrupt.emplace(std::move(e));
            tprf::request_cancel(SIGINT);
        }
    }
    {
        py::gil_scoped_release nogil;
        worker.join();
    }
    if (interrupt) throw std::move(*interrupt);
    if (failure) std::rethrow_exception(failure);
    return std::move(*value);
}

// A numpy view of `a`, which lives as long as `owner`: no copy. Read-only where the owner is const
// (a Result's arrays: every access must see what the render computed).
template <class Owner, class Array>
py::array share(const std::shared_ptr<Owner>& owner, const Array& a) {
    auto* keep = new std::shared_ptr<Owner>(owner);
    py::capsule base(keep, [](void* p) { delete static_cast<std::shared_ptr<Owner>*>(p); });
    std::vector<py::ssize_t> shape(a.shape.begin(), a.shape.end());
    py::array_t<typename decltype(a.data)::value_type> view(shape, a.data.data(), base);
    if (std::is_const_v<Owner>) view.attr("flags").attr("writeable") = false;
    return view;
}

// The common options, checked as the command line checks its flags.
void check_options(int threads, double max_memory_gb) {
    if (threads < 0 || threads > 4096)
        throw tprf::Error("threads: must be 0 (all cores) to 4096, not " + std::to_string(threads));
    if (!(std::isfinite(max_memory_gb) && max_memory_gb >= 0.0))
        throw tprf::Error("max_memory_gb: must be 0 (80% of the memory available) or a positive number of GB");
}

py::object array_or_none(const PyResult& r, const std::string& name) {
    const auto it = r.result->arrays.find(name);
    if (it == r.result->arrays.end()) return py::none();
    return share(r.result, it->second);
}

template <class Owner>
py::dict arrays_dict(const std::shared_ptr<Owner>& r) {
    py::dict d;
    for (const auto& [name, a] : r->arrays) d[py::str(name)] = share(r, a);
    for (const auto& [name, a] : r->labels) d[py::str(name)] = share(r, a);
    return d;
}

// A scene (or sensor) given as a dict: its JSON text through Python's json module, so that the
// parser sees exactly what a file with the same content would hold. numpy's scalars and arrays (whatever
// has `tolist`) are written as the numbers and lists they hold.
std::string json_text(const py::dict& d) {
    const py::cpp_function plain([](const py::object& o) -> py::object {
        if (py::hasattr(o, "tolist")) return o.attr("tolist")();
        throw py::type_error("Object of type " + py::str(py::type::of(o).attr("__name__")).cast<std::string>() +
                             " is not JSON serializable");
    });
    return py::module_::import("json")
        .attr("dumps")(d, py::arg("allow_nan") = true, py::arg("default") = plain)
        .cast<std::string>();
}

// `defines` as -D takes them: each name with its value as text (str() of any scalar: 4, 0.5, "x").
tprf::XmlDefines define_texts(const py::dict& defines) {
    tprf::XmlDefines out;
    for (const auto& [name, value] : defines) out[py::str(name).cast<std::string>()] = py::str(value).cast<std::string>();
    return out;
}

PyScene load_scene(const py::object& source, std::optional<double> max_edge, const py::object& base,
                   const py::dict& define_values) {
    const tprf::XmlDefines defines = define_texts(define_values);
    tprf::Scene scene;
    if (py::isinstance<py::dict>(source)) {
        if (!defines.empty()) throw tprf::Error("defines: apply to Mitsuba XML scene files only, not to a dict");
        const std::filesystem::path dir = base.is_none() ? std::filesystem::path() : base.cast<std::filesystem::path>();
        scene = tprf::parse_scene(json_text(source.cast<py::dict>()), dir / "<dict>");
    } else {
        scene = tprf::load_scene(source.cast<std::filesystem::path>(), defines);
    }
    if (max_edge) {
        if (!(std::isfinite(*max_edge) && *max_edge > 0.0))
            throw tprf::Error("max_edge: must be a positive number of metres, not " + std::to_string(*max_edge));
        scene.max_edge = *max_edge;
    }
    return {std::make_shared<const tprf::Scene>(std::move(scene))};
}

py::dict time_dict(const tprf::TimeAxis& t) {
    py::dict d;
    d["bins"] = t.bins;
    d["bin_width"] = t.bin_width;
    d["start"] = t.start;
    d["unit"] = t.unit == tprf::TimeUnit::Metres ? "m" : "ps";
    return d;
}

py::dict phase_seconds(const tprf::PhaseSeconds& s) {
    py::dict d;
    d["load"] = s.load;
    d["patches"] = s.patches;
    d["links"] = s.links;
    d["gather"] = s.gather;
    d["solve"] = s.solve;
    d["write"] = s.write;
    d["total"] = s.total;
    return d;
}

py::dict estimate_dict(const tprf::ResourceEstimate& e) {
    py::dict d;
    d["patches"] = e.patches;
    d["links"] = e.links;
    d["peak_bytes"] = e.peak_bytes;
    d["peak_stage"] = e.peak_stage;
    d["link_bytes"] = e.link_bytes;
    d["cube_bytes"] = e.cube_bytes;
    d["solver_bytes"] = e.solver_bytes;
    d["seconds"] = phase_seconds(e.seconds);
    d["capture_batch"] = e.capture_batch;
    d["capture_marches"] = e.capture_marches;
    return d;
}

// tprf.info: the estimate (before anything heavy), then the patches and links built and counted,
// as `tprf info` prints them; `links=False` stops after the estimate.
py::dict info(const PyScene& s, int threads, bool links, const py::object& progress, double max_memory_gb) {
    check_options(threads, max_memory_gb);
    tprf::PipelineOptions options;
    options.threads = threads;
    options.max_memory_gb = max_memory_gb;
    const tprf::Scene& scene = *s.scene;
    py::dict d;
    d["scene"] = scene.file.string();
    d["time"] = time_dict(scene.time);
    d["time_text"] = tprf::describe_time(scene.time);
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, options);
    d["estimate"] = estimate_dict(e);
    const std::size_t limit = tprf::memory_limit_bytes(options);
    d["memory_limit_bytes"] = limit;
    if (!links || e.link_stage_bytes > limit) return d;
    const tprf::SceneSummary summary = run_cancellable(
        [&](const tprf::ProgressFn& p) {
            tprf::PipelineOptions o = options;
            o.progress = p;
            return tprf::describe_scene(scene, o);
        },
        progress);
    d["patches"] = summary.patches;
    d["max_edge"] = summary.max_edge;
    d["links"] = summary.links;
    d["mirror_links"] = summary.mirror_links;
    d["glossy_rows"] = summary.glossy_rows;
    d["link_bytes"] = summary.link_bytes;
    d["clusters"] = summary.clusters;
    d["seconds"] = py::dict(py::arg("patches") = summary.seconds_patches, py::arg("links") = summary.seconds_links);
    return d;
}

// render's `aov`: None, a comma-separated string or a list of names, as --aov takes them.
unsigned aov_maps(const py::object& aov) {
    if (aov.is_none()) return 0;
    if (py::isinstance<py::str>(aov)) return tprf::parse_aov_list(aov.cast<std::string>(), "aov");
    std::string list;
    for (const py::handle name : aov) {
        if (!list.empty()) list += ',';
        list += py::str(name).cast<std::string>();
    }
    return tprf::parse_aov_list(list, "aov");
}

PyResult render(const PyScene& s, int threads, const py::object& progress, bool patch_profiles,
                double max_memory_gb, const py::object& aov) {
    check_options(threads, max_memory_gb);
    tprf::RenderOptions options;
    options.aovs = aov_maps(aov);
    options.threads = threads;
    options.patch_profiles = patch_profiles;
    options.max_memory_gb = max_memory_gb;
    options.draw_plots = false;
    auto result = run_cancellable(
        [&](const tprf::ProgressFn& p) {
            tprf::RenderOptions o = options;
            o.progress = p;
            return tprf::render_scene(*s.scene, o);
        },
        progress);
    return {std::make_shared<const tprf::RenderResult>(std::move(result))};
}

// A numpy array as a result to measure: (H, W, T, 3) a camera's cube, (T, nu, nv) or (T, nu_l, nv_l,
// nu_s, nv_s) a capture's H, time first; `time` the axis (a dict as Result.time; `bins` from the
// array when left out).
std::shared_ptr<const tprf::RenderResult> array_result(const py::object& x, const py::object& time) {
    const auto a = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(x);
    if (!a) throw tprf::Error("apply_sensor: expected a tprf.Result or a numpy array");
    const bool camera = a.ndim() == 4;
    if (!camera && a.ndim() != 3 && a.ndim() != 5)
        throw tprf::Error("apply_sensor: an array must be a camera cube (H, W, T, 3) or a capture (T, nu, nv) or "
                          "(T, nu_l, nv_l, nu_s, nv_s), not of " + std::to_string(a.ndim()) + " dimensions");
    for (py::ssize_t k = 0; k < a.ndim(); ++k)
        if (a.shape(k) == 0) throw tprf::Error("apply_sensor: the array has no elements along axis " + std::to_string(k));
    if (camera && a.shape(3) != 3)
        throw tprf::Error("apply_sensor: a camera cube's last axis holds the 3 channels, not " + std::to_string(a.shape(3)));
    if (time.is_none() || !py::isinstance<py::dict>(time))
        throw tprf::Error("apply_sensor: an array needs its time axis: time={\"bin_width\": ..., \"start\": ..., \"unit\": ...}");
    py::dict axis = py::dict(time.cast<py::dict>());
    const py::ssize_t T = camera ? a.shape(2) : a.shape(0);
    if (!axis.contains("bins")) axis["bins"] = T;
    auto result = std::make_shared<tprf::RenderResult>();
    result->time = tprf::parse_time_block(json_text(axis), "<time>", "time");
    if (result->time.bins != int(T))
        throw tprf::Error("apply_sensor: time[\"bins\"] is " + std::to_string(result->time.bins) + " but the array's time axis has " +
                          std::to_string(T) + " bins");
    tprf::FloatArray& cube = result->arrays[camera ? "transient" : "capture"];
    cube.shape.assign(a.shape(), a.shape() + a.ndim());
    cube.data.assign(a.data(), a.data() + a.size());
    return result;
}

// tprf.apply_sensor: a sensor block (a dict, or a file path) applied to a result or an array.
py::dict apply_sensor(const py::object& x, const py::object& sensor, int threads, const py::object& time) {
    check_options(threads, 0.0);
    const tprf::SensorSettings settings =
        py::isinstance<py::dict>(sensor)
            ? tprf::parse_sensor_block(json_text(sensor.cast<py::dict>()), "<dict>", "sensor")
            : tprf::load_sensor(sensor.cast<std::filesystem::path>());
    std::shared_ptr<const tprf::RenderResult> input;
    if (py::isinstance<PyResult>(x)) {
        if (!time.is_none()) throw tprf::Error("apply_sensor: a Result carries its own time axis: leave out time");
        input = x.cast<const PyResult&>().result;
    } else {
        input = array_result(x, time);
    }
    auto out = std::make_shared<tprf::RenderResult>();
    out->arrays = run_cancellable([&](const tprf::ProgressFn&) { return tprf::measure(settings, *input, threads); },
                                  py::none());
    return arrays_dict(out);
}

py::object scene_camera(const PyScene& s) {
    if (!s.scene->camera) return py::none();
    const tprf::Camera& c = *s.scene->camera;
    py::dict d;
    d["width"] = c.width;
    d["height"] = c.height;
    d["spp"] = c.spp;
    if (c.intrinsics) {
        d["intrinsics"] = py::dict(py::arg("fx") = c.intrinsics->fx, py::arg("fy") = c.intrinsics->fy,
                                   py::arg("cx") = c.intrinsics->cx, py::arg("cy") = c.intrinsics->cy);
    } else {
        d["fov"] = c.fov_deg;
    }
    if (!c.distortion.none())
        d["distortion"] = py::dict(py::arg("k1") = c.distortion.k1, py::arg("k2") = c.distortion.k2,
                                   py::arg("k3") = c.distortion.k3, py::arg("p1") = c.distortion.p1,
                                   py::arg("p2") = c.distortion.p2);
    d["unwarp"] = c.unwarp;
    d["footprint"] = c.footprint;
    d["shift_second_bounce"] = c.shift_second_bounce;
    return d;
}

void translate_exceptions(py::module_& m) {
    // tprf.Error is a ValueError: bad input, with the command line's message.
    static py::exception<tprf::Error> error(m, "Error", PyExc_ValueError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const tprf::Error& e) {
            error(e.what());
        } catch (const tprf::OutputError& e) {
            PyErr_SetString(PyExc_OSError, e.what());
        } catch (const tprf::Cancelled& e) {
            PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
        }
    });
}

}  // namespace

PYBIND11_MODULE(_tprf, m) {
    m.doc() = "tprf: transient radiosity renderer (docs/python.md)";
    m.attr("__version__") = TPRF_VERSION;
    translate_exceptions(m);

    py::class_<PyScene>(m, "Scene", "A loaded, validated scene (tprf.load_scene).")
        .def_property_readonly("file", [](const PyScene& s) { return s.scene->file.string(); })
        .def_property_readonly("time", [](const PyScene& s) { return time_dict(s.scene->time); })
        .def_property_readonly("camera", &scene_camera)
        .def_property_readonly("has_capture", [](const PyScene& s) { return s.scene->capture.has_value(); })
        .def_property_readonly("objects", [](const PyScene& s) { return s.scene->objects.size(); })
        .def_property_readonly("max_edge", [](const PyScene& s) { return s.scene->max_edge; })
        .def("__repr__", [](const PyScene& s) {
            return "<tprf.Scene '" + s.scene->file.string() + "': " + std::to_string(s.scene->objects.size()) +
                   " objects, " + tprf::describe_time(s.scene->time) + ">";
        });

    py::class_<PyResult>(m, "Result", "What tprf.render computed. Arrays share the result's memory.")
        .def_property_readonly("transient", [](const PyResult& r) { return array_or_none(r, "transient"); },
                               "float32 (H, W, T, 3): radiance per pixel and time bin")
        .def_property_readonly("steady", [](const PyResult& r) { return array_or_none(r, "steady"); },
                               "float32 (H, W, 3): steady-state radiance")
        .def_property_readonly("patch_transient", [](const PyResult& r) { return array_or_none(r, "patch_transient"); },
                               "float32 (N, T, 3): radiosity per patch and bin (render(patch_profiles=True))")
        .def_property_readonly("patch_steady", [](const PyResult& r) { return array_or_none(r, "patch_steady"); },
                               "float32 (N, 3): steady radiosity per patch (render(patch_profiles=True))")
        .def_property_readonly("capture", [](const PyResult& r) { return array_or_none(r, "capture"); },
                               "float32 (T, nu, nv) or (T, nu_l, nv_l, nu_s, nv_s): the capture's H")
        .def_property_readonly("measurements", [](const PyResult& r) { return array_or_none(r, "measurements"); },
                               "float32 (H, W, K, 3): the scene's sensor block")
        .def_property_readonly("depth", [](const PyResult& r) { return array_or_none(r, "depth"); },
                               "float32 (H, W): an amcw sensor's depth")
        .def_property_readonly("aov", [](const PyResult& r) {
                                   py::dict d;
                                   for (const auto& [name, array] : arrays_dict(r.result)) {
                                       const std::string key = name.cast<std::string>();
                                       if (key.rfind("aov_", 0) == 0) d[py::str(key.substr(4))] = array;
                                   }
                                   return d;
                               },
                               "the ground truth maps of render(aov=...) by name: depth (H, W), normal, position, "
                               "albedo (H, W, 3) float32, object (H, W) int32")
        .def_property_readonly("arrays", [](const PyResult& r) { return arrays_dict(r.result); },
                               "every array by its output file's name (without .npy)")
        .def_property_readonly("time", [](const PyResult& r) { return time_dict(r.result->time); })
        .def_property_readonly("record", [](const PyResult& r) { return r.result->record; },
                               "render.json's text")
        .def("__repr__", [](const PyResult& r) {
            std::string text = "<tprf.Result:";
            for (const auto& [name, a] : r.result->arrays) {
                text += " " + name + " (";
                for (std::size_t k = 0; k < a.shape.size(); ++k) text += (k ? ", " : "") + std::to_string(a.shape[k]);
                text += ")";
            }
            char seconds[32];
            std::snprintf(seconds, sizeof seconds, "%.2f", r.result->report.seconds.total);
            return text + "; " + std::to_string(r.result->report.patches) + " patches, " + seconds + " s>";
        });

    m.def("load_scene", &load_scene, py::arg("scene"), py::arg("max_edge") = py::none(), py::arg("base") = py::none(),
          py::arg("defines") = py::dict(),
          "Loads a scene from a file path (JSON, or Mitsuba 3 XML with `defines` as -D name=value) or a dict "
          "(the scene JSON of docs/scene.md); `base`: the folder that a dict's relative mesh paths start from (default: the "
          "working directory). Raises tprf.Error (a ValueError).");
    m.def("info", &info, py::arg("scene"), py::arg("threads") = 0, py::arg("links") = true,
          py::arg("progress") = py::none(), py::arg("max_memory_gb") = 0.0,
          "The estimate of a render and (links=True) the patches and links built and counted.");
    m.def("render", &render, py::arg("scene"), py::arg("threads") = 0, py::arg("progress") = py::none(),
          py::arg("patch_profiles") = false, py::arg("max_memory_gb") = 0.0, py::arg("aov") = py::none(),
          "Renders in memory; progress(phase, fraction) is called in order on this thread. Ctrl-C cancels. "
          "aov: ground truth maps (\"depth,normal\", a list of names, or \"all\") into result.arrays['aov_NAME'].");
    m.def("apply_sensor", &apply_sensor, py::arg("result"), py::arg("sensor"), py::arg("threads") = 0,
          py::arg("time") = py::none(),
          "A sensor block (a dict or a file) applied to a Result, or to a numpy array: a camera cube (H, W, T, 3) or "
          "a capture (T, ...), with time={'bin_width': ..., 'start': ..., 'unit': ...}: {'measurements': ..., "
          "'depth': ..., 'raw': ...}.");
}
