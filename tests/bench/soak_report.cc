#include "tests/bench/soak_report.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>

namespace stevi::soak {
namespace {

constexpr double kLowestMs = 0.05;
const double kLogStep = std::log(1.01);

std::string Format(const char* format, ...) __attribute__((format(printf, 1, 2)));
std::string Format(const char* format, ...) {
  char buf[512];
  va_list args;
  va_start(args, format);
  std::vsnprintf(buf, sizeof buf, format, args);
  va_end(args);
  return buf;
}

// Both the console and report.txt.
class Out {
 public:
  explicit Out(const std::string& path) : file_(path) {}
  void Line(const std::string& text) {
    std::printf("%s\n", text.c_str());
    file_ << text << "\n";
  }

 private:
  std::ofstream file_;
};

// Samples whose time lies in [from, to] (seconds, with a little slack).
bool In(double t, double from, double to) { return t >= from - 1 && t <= to + 1; }

struct Periods {
  double first_from, first_to, last_from, last_to;
};

Periods PeriodsOf(const SoakResult& r) {
  const double end = r.samples.empty() ? 0 : r.samples.back().t_s;
  const double w = r.warmup_minutes * 60, c = r.compare_minutes * 60;
  return {w, w + c, std::max(w, end - c), end};
}

// The windows (by the index of the sample that closed them) wholly inside [from, to].
std::vector<size_t> WindowsIn(const SoakResult& r, double from, double to) {
  std::vector<size_t> out;
  for (size_t k = 1; k < r.samples.size(); ++k) {
    if (r.samples[k - 1].t_s >= from - 1 && r.samples[k].t_s <= to + 1) out.push_back(k);
  }
  return out;
}

double P(const LatencyHist& h, double q) { return h.count() == 0 ? NAN : h.Quantile(q); }

// ---------------------------------------------------------------------------------------------
// The plot.

const cv::Scalar kColours[] = {{200, 60, 30}, {40, 140, 40}, {30, 30, 200}, {160, 40, 160},
                               {0, 140, 200}, {120, 120, 0}, {90, 90, 90},  {0, 200, 120}};

struct Series {
  std::string name;
  std::vector<cv::Point2d> points;  // (minutes, value); NaN values break the line
};

// `bound`, when finite, is drawn as a dashed red line (a check's limit) and kept in view.
void DrawPanel(cv::Mat& img, cv::Rect area, const std::string& title, const std::string& unit,
               const std::vector<Series>& series, const SoakResult& r, double end_min,
               double bound = NAN) {
  const int left = area.x + 70, right = area.x + area.width - 170, top = area.y + 24,
            bottom = area.y + area.height - 28;
  double ymin = 0, ymax = std::isfinite(bound) ? bound : 0;
  for (const Series& s : series) {
    for (const cv::Point2d& p : s.points) {
      if (!std::isfinite(p.y)) continue;
      ymax = std::max(ymax, p.y);
      ymin = std::min(ymin, p.y);
    }
  }
  ymax = ymax <= 0 ? 1 : ymax * 1.15;
  ymin *= 1.15;
  // A round step for the y ticks.
  const double raw = (ymax - ymin) / 5, mag = std::pow(10, std::floor(std::log10(raw)));
  const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
  ymax = std::ceil(ymax / step) * step;
  ymin = std::floor(ymin / step) * step;
  const double xmax = std::max(end_min, 1e-3);
  auto X = [&](double m) { return left + static_cast<int>((right - left) * m / xmax); };
  auto Y = [&](double v) {
    return bottom - static_cast<int>((bottom - top) * (v - ymin) / (ymax - ymin));
  };
  // Warm-up, the compared periods, outages.
  const Periods p = PeriodsOf(r);
  cv::Mat overlay = img.clone();
  cv::rectangle(overlay, {X(0), top}, {X(std::min(r.warmup_minutes, xmax)), bottom},
                {225, 225, 225}, cv::FILLED);
  cv::rectangle(overlay, {X(p.first_from / 60), top}, {X(p.first_to / 60), top + 8},
                {230, 190, 140}, cv::FILLED);
  cv::rectangle(overlay, {X(p.last_from / 60), top}, {X(p.last_to / 60), top + 8}, {230, 190, 140},
                cv::FILLED);
  for (const Event& e : r.events) {
    if (e.server != 1) continue;
    const double until = e.first_frame_s >= 0 ? e.first_frame_s : e.recovered_s;
    cv::rectangle(overlay, {X(e.t_s / 60), top},
                  {std::max(X(until / 60), X(e.t_s / 60) + 2), bottom}, {120, 190, 250},
                  cv::FILLED);
  }
  cv::addWeighted(overlay, 0.6, img, 0.4, 0, img);
  for (const Event& e : r.events) {
    if (e.server == 0)
      cv::line(img, {X(e.t_s / 60), top}, {X(e.t_s / 60), bottom}, {40, 40, 220}, 1);
  }
  // Axes, grid, ticks.
  cv::rectangle(img, {left, top}, {right, bottom}, {0, 0, 0}, 1);
  for (double v = ymin; v <= ymax + 1e-9; v += step) {
    cv::line(img, {left, Y(v)}, {right, Y(v)}, {210, 210, 210}, 1);
    cv::putText(img, Format("%g", v), {area.x + 4, Y(v) + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {0, 0, 0}, 1, cv::LINE_AA);
  }
  const double xstep = xmax <= 1.5 ? 0.25 : xmax <= 3 ? 0.5 : xmax <= 8 ? 1 : xmax <= 20 ? 2 : 5;
  for (double m = 0; m <= xmax + 1e-9; m += xstep) {
    cv::line(img, {X(m), bottom}, {X(m), bottom + 4}, {0, 0, 0}, 1);
    cv::putText(img, Format("%g", m), {X(m) - 6, bottom + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {0, 0, 0}, 1, cv::LINE_AA);
  }
  cv::putText(img, title + " (" + unit + ")", {left, area.y + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.55,
              {0, 0, 0}, 1, cv::LINE_AA);
  if (std::isfinite(bound)) {
    for (int x = left; x < right; x += 12) {
      cv::line(img, {x, Y(bound)}, {std::min(x + 6, right), Y(bound)}, {30, 30, 220}, 1);
    }
  }
  // The series, and their legend.
  for (size_t i = 0; i < series.size(); ++i) {
    const cv::Scalar colour = kColours[i % std::size(kColours)];
    const Series& s = series[i];
    for (size_t j = 0; j < s.points.size(); ++j) {
      const cv::Point2d& a = s.points[j];
      if (!std::isfinite(a.y)) continue;
      cv::circle(img, {X(a.x), Y(a.y)}, 2, colour, cv::FILLED, cv::LINE_AA);
      if (j + 1 < s.points.size() && std::isfinite(s.points[j + 1].y)) {
        cv::line(img, {X(a.x), Y(a.y)}, {X(s.points[j + 1].x), Y(s.points[j + 1].y)}, colour, 2,
                 cv::LINE_AA);
      }
    }
    const int ly = top + 10 + static_cast<int>(i) * 17;
    cv::line(img, {right + 12, ly - 4}, {right + 32, ly - 4}, colour, 2, cv::LINE_AA);
    cv::putText(img, s.name, {right + 38, ly}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1,
                cv::LINE_AA);
  }
}

void DrawPlot(const SoakResult& r, const std::string& path) {
  const int width = 1400, panel = 250;
  cv::Mat img(panel * 4 + 60, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const double end_min = r.samples.empty() ? 1 : r.samples.back().t_s / 60;
  std::vector<Series> rss, fds, threads;
  for (size_t i = 0; i < r.process_names.size(); ++i) {
    Series a{r.process_names[i], {}}, b = a, c = a;
    bool any = false;
    // Memory as the change from the process's last sample of the warm-up: the growth the check
    // judges, at a scale where a few per cent show.
    double reference_kb = NAN;
    for (const Sample& s : r.samples) {
      if (s.procs[i].ok && s.t_s <= r.warmup_minutes * 60 + 1) {
        reference_kb = static_cast<double>(s.procs[i].rss_kb);
      }
    }
    for (const Sample& s : r.samples) {
      const ProcSample& p = s.procs[i];
      any = any || p.ok;
      a.points.push_back(
          {s.t_s / 60, p.ok ? 100.0 * (static_cast<double>(p.rss_kb) / reference_kb - 1) : NAN});
      b.points.push_back({s.t_s / 60, p.ok ? p.fds : NAN});
      c.points.push_back({s.t_s / 60, p.ok ? p.threads : NAN});
    }
    if (!any) continue;
    rss.push_back(a);
    fds.push_back(b);
    threads.push_back(c);
  }
  std::vector<Series> latency;
  for (size_t g = 0; g < r.group_names.size(); ++g) {
    Series s{r.group_names[g] + " p99", {}};
    bool any = false;
    for (size_t k = 1; k < r.samples.size(); ++k) {
      const StreamWindow& w = r.samples[k].streams[g];
      any = any || w.clients > 0;
      s.points.push_back({(r.samples[k - 1].t_s + r.samples[k].t_s) / 120, P(w.latency, 0.99)});
    }
    if (any) latency.push_back(s);
  }
  DrawPanel(img, {0, 40, width, panel},
            "resident memory per process, change since the warm-up's end; dashed: the 5 % bound",
            "%", rss, r, end_min, 5.0);
  DrawPanel(img, {0, 40 + panel, width, panel}, "open file descriptors", "count", fds, r, end_min);
  DrawPanel(img, {0, 40 + 2 * panel, width, panel}, "threads", "count", threads, r, end_min);
  DrawPanel(img, {0, 40 + 3 * panel, width, panel},
            "capture-to-client latency p99 per window, outside outages", "ms", latency, r, end_min);
  cv::putText(img,
              "stevi-soak: minutes on the x axis; grey = warm-up, blue bars = compared periods, "
              "red lines = server-A restarts, orange = camera losses (until frames resume)",
              {10, 24}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1, cv::LINE_AA);
  cv::imwrite(path, img);
}

}  // namespace

void LatencyHist::Add(double ms) {
  int i = 0;
  if (ms > kLowestMs) i = static_cast<int>(std::log(ms / kLowestMs) / kLogStep);
  bins_[static_cast<size_t>(std::clamp(i, 0, kBins - 1))]++;
  ++n_;
  max_ms_ = std::max(max_ms_, ms);
}

void LatencyHist::Merge(const LatencyHist& other) {
  for (size_t i = 0; i < bins_.size(); ++i) bins_[i] += other.bins_[i];
  n_ += other.n_;
  max_ms_ = std::max(max_ms_, other.max_ms_);
}

void LatencyHist::Clear() {
  std::fill(bins_.begin(), bins_.end(), 0);
  n_ = 0;
  max_ms_ = 0;
}

double LatencyHist::Quantile(double q) const {
  if (n_ == 0) return 0;
  const double want = q * static_cast<double>(n_);
  uint64_t seen = 0;
  for (size_t i = 0; i < bins_.size(); ++i) {
    seen += bins_[i];
    if (static_cast<double>(seen) >= want && seen > 0) {
      return std::min(max_ms_, kLowestMs * std::exp(kLogStep * static_cast<double>(i + 1)));
    }
  }
  return max_ms_;
}

void StreamWindow::Merge(const StreamWindow& o) {
  min_client_delivered = clients == 0 ? o.min_client_delivered
                                      : std::min(min_client_delivered, o.min_client_delivered);
  clients += o.clients;
  delivered += o.delivered;
  delivered_in_outage += o.delivered_in_outage;
  lost += o.lost;
  lost_in_outage += o.lost_in_outage;
  dropped += o.dropped;
  dropped_in_outage += o.dropped_in_outage;
  resets += o.resets;
  images += o.images;
  latency.Merge(o.latency);
}

// The groups that had clients.
std::vector<size_t> ShownGroups(const SoakResult& r) {
  std::vector<size_t> groups;
  for (size_t g = 0; g < r.group_names.size(); ++g) {
    bool any = false;
    for (const Sample& s : r.samples) any = any || s.streams[g].clients > 0;
    if (any) groups.push_back(g);
  }
  return groups;
}

void WriteCsvFiles(const SoakResult& r, const std::string& out_dir) {
  std::ofstream f(out_dir + "/samples.csv");
  f << "t_s,process,pid,alive,rss_kb,fds,threads\n";
  for (const Sample& s : r.samples) {
    for (size_t i = 0; i < r.process_names.size(); ++i) {
      const ProcSample& p = s.procs[i];
      if (s.pids[i] <= 0) continue;
      f << Format("%.1f,%s,%d,%d,%ld,%d,%d\n", s.t_s, r.process_names[i].c_str(), s.pids[i],
                  p.ok ? 1 : 0, p.rss_kb, p.fds, p.threads);
    }
  }
  std::ofstream t(out_dir + "/threads.csv");
  t << "t_s,process,thread_name,count\n";
  for (const Sample& s : r.samples) {
    for (size_t i = 0; i < r.process_names.size(); ++i) {
      if (s.pids[i] <= 0 || !s.procs[i].ok) continue;
      for (const auto& [name, count] : s.procs[i].thread_names) {
        t << Format("%.1f,%s,%s,%d\n", s.t_s, r.process_names[i].c_str(), name.c_str(), count);
      }
    }
  }
  std::ofstream w(out_dir + "/windows.csv");
  w << "window,t_from_s,t_to_s,group,clients,delivered,fewest_per_client,delivered_in_outage,"
       "lost,lost_in_outage,dropped,dropped_in_outage,resets,images,p50_ms,p99_ms,max_ms\n";
  std::ofstream st(out_dir + "/status.csv");
  st << "t_s,fps_out_A,state_A,fps_out_B,state_B,obstacle_distance,export_points\n";
  for (size_t k = 1; k < r.samples.size(); ++k) {
    const Sample& s = r.samples[k];
    for (size_t g = 0; g < r.group_names.size(); ++g) {
      const StreamWindow& x = s.streams[g];
      if (x.clients == 0) continue;
      w << Format(
          "%zu,%.1f,%.1f,%s,%d,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.2f,%.2f,%.2f\n", k,
          r.samples[k - 1].t_s, s.t_s, r.group_names[g].c_str(), x.clients,
          static_cast<unsigned long long>(x.delivered),
          static_cast<unsigned long long>(x.min_client_delivered),
          static_cast<unsigned long long>(x.delivered_in_outage),
          static_cast<unsigned long long>(x.lost),
          static_cast<unsigned long long>(x.lost_in_outage),
          static_cast<unsigned long long>(x.dropped),
          static_cast<unsigned long long>(x.dropped_in_outage),
          static_cast<unsigned long long>(x.resets), static_cast<unsigned long long>(x.images),
          P(x.latency, 0.5), P(x.latency, 0.99), x.latency.max_ms());
    }
    st << Format("%.1f,%.2f,%s,%.2f,%s,%llu,%lld\n", s.t_s, s.fps_out[0], s.source_state[0].c_str(),
                 s.fps_out[1], s.source_state[1].c_str(),
                 static_cast<unsigned long long>(s.obstacle_distance),
                 static_cast<long long>(s.export_points));
  }
  std::ofstream e(out_dir + "/events.csv");
  e << "t_s,event,stop_ms,recovered_s,first_frame_s\n";
  for (const Event& x : r.events) {
    e << Format("%.1f,%s,%.0f,%.1f,%.1f\n", x.t_s, x.what.c_str(), x.stop_ms, x.recovered_s,
                x.first_frame_s);
  }
}

void PrintProcesses(Out& out, const SoakResult& r) {
  // Table 1: the processes.
  out.Line("");
  out.Line("Processes: resident memory MB / open descriptors / threads (- = not running)");
  std::string header = "  t min |";
  std::vector<size_t> shown;
  for (size_t i = 0; i < r.process_names.size(); ++i) {
    bool any = false;
    for (const Sample& s : r.samples) any = any || s.procs[i].ok;
    if (!any) continue;
    shown.push_back(i);
    header += Format(" %-16s|", r.process_names[i].c_str());
  }
  out.Line(header);
  for (const Sample& s : r.samples) {
    std::string line = Format(" %6.2f |", s.t_s / 60);
    for (const size_t i : shown) {
      const ProcSample& p = s.procs[i];
      line += p.ok ? Format(" %6.1f/%3d/%3d  |", p.rss_kb / 1024.0, p.fds, p.threads)
                   : std::string(" -               |");
    }
    out.Line(line);
  }
}

void PrintStreams(Out& out, const SoakResult& r, const std::vector<size_t>& groups) {
  // Table 2: the streams.
  out.Line("");
  out.Line(
      "Streams per window, outside outages: frames (fewest per client) / lost / dropped / "
      "p50 / p99 ms; in outages: frames, lost");
  std::string h2 = " window min |";
  for (const size_t g : groups) h2 += Format(" %-36s|", r.group_names[g].c_str());
  h2 += " WS img | A fps | B state     | OD/s | export";
  out.Line(h2);
  for (size_t k = 1; k < r.samples.size(); ++k) {
    const Sample& s = r.samples[k];
    std::string line = Format(" %4.1f-%4.1f  |", r.samples[k - 1].t_s / 60, s.t_s / 60);
    uint64_t images = 0;
    for (const size_t g : groups) {
      const StreamWindow& x = s.streams[g];
      images += x.images;
      line += Format(" %5llu(%4llu) %llu %llu %5.1f %6.1f; %3llu %llu |",
                     static_cast<unsigned long long>(x.delivered),
                     static_cast<unsigned long long>(x.min_client_delivered),
                     static_cast<unsigned long long>(x.lost),
                     static_cast<unsigned long long>(x.dropped), P(x.latency, 0.5),
                     P(x.latency, 0.99), static_cast<unsigned long long>(x.delivered_in_outage),
                     static_cast<unsigned long long>(x.lost_in_outage));
    }
    const double window_s = s.t_s - r.samples[k - 1].t_s;
    line += Format(" %6llu | %5.1f | %-11s | %4.1f | %lld", static_cast<unsigned long long>(images),
                   s.fps_out[0], s.source_state[1].c_str(),
                   window_s > 0 ? static_cast<double>(s.obstacle_distance) / window_s : 0.0,
                   static_cast<long long>(s.export_points));
    out.Line(line);
  }
}

void PrintEvents(Out& out, const SoakResult& r) {
  // Table 3: the events.
  out.Line("");
  out.Line(
      "Events: time, what, SIGTERM to exit, recovered (serving / camera started) after, "
      "first frame after (the outage)");
  for (const Event& e : r.events) {
    out.Line(Format(
        " %7.1f s  %-18s %6s  +%5.1f s  %s", e.t_s, e.what.c_str(),
        e.server == 0 ? Format("%.0f ms", e.stop_ms).c_str() : "-", e.recovered_s - e.t_s,
        e.first_frame_s >= 0 ? Format("+%.1f s", e.first_frame_s - e.t_s).c_str() : "never"));
  }
  out.Line("Shutdown at the end:");
  for (const std::string& s : r.shutdown) out.Line("  " + s);
}

// A process's most memory, descriptors and threads (and threads of each name) in a period.
struct ProcessMaxima {
  bool any = false;
  long rss_kb = 0;
  int fds = 0;
  int threads = 0;
  std::map<std::string, int> thread_names;

  void Add(const ProcSample& p) {
    any = true;
    rss_kb = std::max(rss_kb, p.rss_kb);
    fds = std::max(fds, p.fds);
    threads = std::max(threads, p.threads);
    for (const auto& [name, count] : p.thread_names) {
      thread_names[name] = std::max(thread_names[name], count);
    }
  }
};

// The done-when checks; true when all pass.
bool Checks(Out& out, const SoakResult& r, const std::vector<size_t>& groups) {
  // The checks.
  const Periods per = PeriodsOf(r);
  out.Line("");
  out.Line(
      Format("Checks (first = %.1f-%.1f min, after the warm-up; last = %.1f-%.1f min; "
             "maxima of the samples in each):",
             per.first_from / 60, per.first_to / 60, per.last_from / 60, per.last_to / 60));
  bool all = true;
  auto check = [&](bool pass, const std::string& text) {
    all = all && pass;
    out.Line(Format("  %-4s %s", pass ? "PASS" : "FAIL", text.c_str()));
  };
  const bool long_enough = per.first_to <= per.last_to + 1 && r.samples.size() > 2;
  if (!long_enough) check(false, "the run is shorter than the warm-up and the compared period");
  for (size_t i = 0; i < r.process_names.size() && long_enough; ++i) {
    ProcessMaxima first, last;
    for (const Sample& s : r.samples) {
      if (!s.procs[i].ok) continue;
      if (In(s.t_s, per.first_from, per.first_to)) first.Add(s.procs[i]);
      if (In(s.t_s, per.last_from, per.last_to)) last.Add(s.procs[i]);
    }
    if (!first.any || !last.any) continue;
    const char* name = r.process_names[i].c_str();
    // The soak itself is the load, not the system under test: its figures are shown, not judged
    // (its 18 gRPC clients' event engine adds a thread under load).
    const bool judged = r.process_names[i] != kHarnessName;
    const auto check_process = [&](bool pass, const std::string& text) {
      if (judged) return check(pass, text);
      out.Line("  info " + text);
    };
    const double growth =
        100.0 * (static_cast<double>(last.rss_kb) / static_cast<double>(first.rss_kb) - 1);
    check_process(growth < 5,
                  Format("%-9s resident memory %.1f -> %.1f MB (%+.1f %%, bound < 5 %%)", name,
                         first.rss_kb / 1024.0, last.rss_kb / 1024.0, growth));
    check_process(last.fds <= first.fds, Format("%-9s file descriptors %d -> %d (must not grow)",
                                                name, first.fds, last.fds));
    std::string grew;  // the names with more threads at most in the last period
    for (const auto& [thread, count] : last.thread_names) {
      const auto before = first.thread_names.find(thread);
      const int was = before == first.thread_names.end() ? 0 : before->second;
      if (count > was) grew += Format(", %s %d -> %d", thread.c_str(), was, count);
    }
    check_process(last.threads <= first.threads,
                  Format("%-9s threads %d -> %d (must not grow)%s", name, first.threads,
                         last.threads, grew.c_str()));
  }
  // The station's export history: full (at its bound) from the warm-up's end on.
  {
    int64_t lo = -1, hi = -1;
    double reached = -1;
    for (const Sample& s : r.samples) {
      if (reached < 0 && s.export_points == r.export_points_bound) reached = s.t_s;
      if (s.t_s + 1 < per.first_from) continue;
      lo = lo < 0 ? s.export_points : std::min(lo, s.export_points);
      hi = std::max(hi, s.export_points);
    }
    check(lo == r.export_points_bound && hi == r.export_points_bound,
          Format("station export history at its bound (%lld points) from the warm-up on: "
                 "%lld-%lld points after the warm-up, bound first reached at %s",
                 static_cast<long long>(r.export_points_bound), static_cast<long long>(lo),
                 static_cast<long long>(hi),
                 reached < 0 ? "never (lower --export-points or run longer)"
                             : Format("%.1f min", reached / 60).c_str()));
  }
  for (const size_t g : groups) {
    StreamWindow total;
    for (size_t k = 1; k < r.samples.size(); ++k) total.Merge(r.samples[k].streams[g]);
    check(total.lost == 0 && total.dropped == 0,
          Format("%-12s frames lost outside outages %llu, dropped %llu (of %llu delivered; in "
                 "outages %llu delivered, %llu lost)",
                 r.group_names[g].c_str(), static_cast<unsigned long long>(total.lost),
                 static_cast<unsigned long long>(total.dropped),
                 static_cast<unsigned long long>(total.delivered),
                 static_cast<unsigned long long>(total.delivered_in_outage),
                 static_cast<unsigned long long>(total.lost_in_outage)));
  }
  for (const size_t g : groups) {
    LatencyHist first, last;
    for (const size_t k : WindowsIn(r, per.first_from, per.first_to)) {
      first.Merge(r.samples[k].streams[g].latency);
    }
    for (const size_t k : WindowsIn(r, per.last_from, per.last_to)) {
      last.Merge(r.samples[k].streams[g].latency);
    }
    const double a = P(first, 0.99), b = P(last, 0.99);
    const std::string text = Format(
        "%-12s p99 latency first %.1f ms (%llu frames), last %.1f ms (%llu frames): %+.1f %%",
        r.group_names[g].c_str(), a, static_cast<unsigned long long>(first.count()), b,
        static_cast<unsigned long long>(last.count()), 100 * (b / a - 1));
    if (g == 0) {
      check(std::isfinite(a) && std::isfinite(b) && std::abs(b / a - 1) <= 0.2,
            text + " (bound: within 20 %)");
    } else {
      out.Line("  info " + text);
    }
  }
  {
    int never = 0;
    for (const Event& e : r.events) never += e.first_frame_s < 0 ? 1 : 0;
    check(never == 0, Format("every outage ended: %zu restarts and camera losses, %d without "
                             "frames after them",
                             r.events.size(), never));
    int unclean = 0;
    for (const std::string& s : r.shutdown) {
      // arv-fake-gv-camera-0.8 has no SIGTERM handler: it dies of the signal, as it should.
      const bool camera = s.rfind("camera-", 0) == 0 && s.find(": signal 15") != std::string::npos;
      unclean += s.find(": exit 0") == std::string::npos && !camera ? 1 : 0;
    }
    check(unclean == 0, Format("every stevi process exited 0 on SIGTERM at the end (%d did not; "
                               "the fake cameras die of the signal)",
                               unclean));
  }
  out.Line(all ? "All checks PASS." : "Some checks FAIL.");

  return all;
}

bool Report(const SoakResult& r, const std::string& out_dir) {
  WriteCsvFiles(r, out_dir);
  Out out(out_dir + "/report.txt");
  out.Line("");
  out.Line("stevi-soak report: " + r.command_line);
  out.Line(
      Format("%.1f minutes sampled every %.0f s; warm-up %.1f min; compared periods %.1f "
             "min; server-A synthetic at %g fps, server-B fake GigE pair at %g fps",
             r.samples.empty() ? 0.0 : r.samples.back().t_s / 60, r.sample_every_s,
             r.warmup_minutes, r.compare_minutes, r.fps, r.camera_fps));

  const std::vector<size_t> groups = ShownGroups(r);
  PrintProcesses(out, r);
  PrintStreams(out, r, groups);
  PrintEvents(out, r);
  const bool all = Checks(out, r, groups);
  DrawPlot(r, out_dir + "/soak.png");
  out.Line("Files: " + out_dir +
           "/{samples,windows,status,events}.csv, report.txt, soak.png, logs/");
  return all;
}

}  // namespace stevi::soak
