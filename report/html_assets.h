// The front end of report.html, embedded at build time (cmake/embed_assets.cmake): the page
// template with its markers, the style sheet and the esbuild bundle of report/web/src with
// three.js. Defined in the generated html_assets.cpp.
#pragma once

#include <string_view>

namespace flank::report::html_assets {

extern const std::string_view kTemplate;  // report/web/template.html
extern const std::string_view kStyle;     // report/web/src/style.css
extern const std::string_view kScript;    // the bundle, licence comments at its end

}  // namespace flank::report::html_assets
