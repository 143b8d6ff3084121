// The software rasteriser's loops (core/render/raster.hpp) on checked frame buffers.
#include "bindings/bindings.hpp"
#include "bindings/arrays.hpp"
#include "render/raster.hpp"

namespace softbody::bindings {
namespace {

/// The image and depth buffer of a frame, checked: (H, W, 3) and (H, W) float64.
softbody::render::Image frame_image(F64 image, F64 zbuffer) {
    check_shape(image, "image", {-1, -1, 3});
    const Index h = static_cast<Index>(image.shape(0)), w = static_cast<Index>(image.shape(1));
    check_shape(zbuffer, "zbuffer", {h, w});
    return {image.data(), zbuffer.data(), h, w};
}

void raster_clear(F64 image, F64 zbuffer, ConstF64 top, ConstF64 bottom) {
    const auto im = frame_image(image, zbuffer);
    check_shape(top, "top", {3});
    check_shape(bottom, "bottom", {3});
    nb::gil_scoped_release release;
    softbody::render::clear(im, top.data(), bottom.data());
}

void raster_triangles(ConstF64 screen, ConstI64 faces, ConstF64 colors, double near, F64 image,
                      F64 zbuffer) {
    const auto im = frame_image(image, zbuffer);
    check_shape(screen, "screen", {-1, 3});
    const Index v = static_cast<Index>(screen.shape(0));
    check_shape(faces, "faces", {-1, 3});
    check_shape(colors, "colors", {v, 3});
    const Index f = static_cast<Index>(faces.shape(0));
    check_indices(faces.data(), 3 * f, 0, v, "faces");
    nb::gil_scoped_release release;
    softbody::render::triangles(im, screen.data(), faces.data(), f, colors.data(), near);
}

void raster_lines(ConstF64 screen_a, ConstF64 screen_b, ConstF64 colors, Index width, double near,
                  double depth_bias, F64 image, F64 zbuffer) {
    const auto im = frame_image(image, zbuffer);
    check_shape(screen_a, "screen_a", {-1, 3});
    const Index count = static_cast<Index>(screen_a.shape(0));
    check_shape(screen_b, "screen_b", {count, 3});
    check_shape(colors, "colors", {count, 3});
    if (width < 1 || width > 64) fail("line width must be from 1 to 64 pixels");
    nb::gil_scoped_release release;
    softbody::render::lines(im, screen_a.data(), screen_b.data(), count, colors.data(), width,
                            near, depth_bias);
}

void raster_downsample(F64 image, Index factor, nb::ndarray<std::uint8_t, nb::c_contig,
                       nb::device::cpu> out) {
    check_shape(image, "image", {-1, -1, 3});
    check_shape(out, "out", {-1, -1, 3});
    const Index h = static_cast<Index>(out.shape(0)), w = static_cast<Index>(out.shape(1));
    if (factor < 1 || h * factor > static_cast<Index>(image.shape(0)) ||
        w * factor > static_cast<Index>(image.shape(1)))
        fail("downsample: out times factor must fit in the image");
    const softbody::render::Image im{image.data(), nullptr, static_cast<Index>(image.shape(0)),
                                     static_cast<Index>(image.shape(1))};
    nb::gil_scoped_release release;
    softbody::render::downsample(im, factor, out.data(), h, w);
}

}  // namespace

void bind_render(nb::module_& mod) {
    mod.def("raster_clear", &raster_clear, nb::arg("image").noconvert(),
            nb::arg("zbuffer").noconvert(), nb::arg("top"), nb::arg("bottom"),
            "Fill image (H, W, 3) with a vertical gradient and reset zbuffer (H, W).");
    mod.def("raster_triangles", &raster_triangles, nb::arg("screen").noconvert(),
            nb::arg("faces").noconvert(), nb::arg("colors").noconvert(), nb::arg("near"),
            nb::arg("image").noconvert(), nb::arg("zbuffer").noconvert(),
            "Depth-tested, Gouraud-shaded triangles into image and zbuffer.");
    mod.def("raster_lines", &raster_lines, nb::arg("screen_a").noconvert(),
            nb::arg("screen_b").noconvert(), nb::arg("colors").noconvert(), nb::arg("width"),
            nb::arg("near"), nb::arg("depth_bias"), nb::arg("image").noconvert(),
            nb::arg("zbuffer").noconvert(), "Depth-tested line segments into image and zbuffer.");
    mod.def("raster_downsample", &raster_downsample, nb::arg("image").noconvert(),
            nb::arg("factor"), nb::arg("out").noconvert(),
            "Average factor x factor blocks of image into out (uint8).");
}

}  // namespace softbody::bindings
