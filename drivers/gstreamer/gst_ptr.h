// Owning pointers for the GStreamer and GLib objects the driver (and its tests) hold: each ref has
// exactly one unref, in the deleter. Include only from .cc files: this header pulls in GStreamer.
#pragma once

#include <memory>

#include <gst/gst.h>

namespace stevi::drivers::gst {

struct ObjectUnref {
  void operator()(gpointer object) const {
    if (object != nullptr) gst_object_unref(object);
  }
};
struct SampleUnref {
  void operator()(GstSample* sample) const { gst_sample_unref(sample); }
};
struct MessageUnref {
  void operator()(GstMessage* message) const { gst_message_unref(message); }
};
struct CapsUnref {
  void operator()(GstCaps* caps) const { gst_caps_unref(caps); }
};
struct ErrorFree {
  void operator()(GError* error) const { g_error_free(error); }
};
struct GFree {
  void operator()(gpointer p) const { g_free(p); }
};
struct ParseContextFree {
  void operator()(GstParseContext* context) const { gst_parse_context_free(context); }
};
struct StrvFree {
  void operator()(gchar** strv) const { g_strfreev(strv); }
};

// A GstObject subclass (element, bus, clock, pad) owned through gst_object_unref.
template <class T>
using ObjectPtr = std::unique_ptr<T, ObjectUnref>;
using ElementPtr = ObjectPtr<GstElement>;
using BusPtr = ObjectPtr<GstBus>;
using ClockPtr = ObjectPtr<GstClock>;
using SamplePtr = std::unique_ptr<GstSample, SampleUnref>;
using MessagePtr = std::unique_ptr<GstMessage, MessageUnref>;
using CapsPtr = std::unique_ptr<GstCaps, CapsUnref>;
using ErrorPtr = std::unique_ptr<GError, ErrorFree>;
using CharPtr = std::unique_ptr<gchar, GFree>;
using ParseContextPtr = std::unique_ptr<GstParseContext, ParseContextFree>;
using StrvPtr = std::unique_ptr<gchar*, StrvFree>;

// Takes ownership of a (transfer floating) element, e.g. from gst_parse_launch_full: sinks a
// floating reference so that the one unref of ElementPtr is the last (a reference that is not
// floating is taken over as it is).
inline ElementPtr AdoptFloating(GstElement* element) {
  if (element != nullptr && g_object_is_floating(element)) gst_object_ref_sink(element);
  return ElementPtr(element);
}

}  // namespace stevi::drivers::gst
