// MuJoCo's renderer on the same software GL as flatland's (OSMesa, llvmpipe), for the comparison
// in docs/BENCHMARKS.md ("Renderer against MuJoCo"): a scene like the butterfly's frame (the
// table, a hand-sized box, the disk) seen from 1.2 m above at 640 x 480, rendered and read back
// (RGB) as fast as it goes for --seconds. MuJoCo's defaults (4x multisampling, shadows,
// reflections, skybox) or, with --plain, without shadows, reflections and skybox (flatland draws
// none of them). The table is a plane of 2 x 2 quads, as coarse as flatland's: MuJoCo draws a
// plane as a grid of its third size's spacing, and the 1 cm grid this harness used first (100 x 100
// quads, --fine-grid) costs MuJoCo work flatland does not do. Prints one JSON object.
//
//   flatland_mujoco_render [--plain] [--fine-grid] [--seconds S]
#include <GL/osmesa.h>
#include <mujoco/mujoco.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

// %s: the plane's grid spacing (m).
static const char* kModelFormat =
    "<mujoco><visual><global offwidth='640' offheight='480'/></visual>"
    "<worldbody><light pos='0 0 2'/>"
    "<geom type='plane' size='0.5 0.5 %s' rgba='0.3 0.3 0.3 1'/>"
    "<geom type='box' pos='0 0.09 0.006' size='0.18 0.02 0.006' rgba='0.8 0.6 0.2 1'/>"
    "<geom type='cylinder' pos='0.05 0.16 0.009' size='0.051 0.003' rgba='0.9 0.9 0.9 1'/>"
    "<camera name='top' pos='0 0 1.2' xyaxes='1 0 0 0 1 0' fovy='29.9'/>"
    "</worldbody></mujoco>";

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char** argv) {
  int plain = 0, fine_grid = 0;
  double seconds = 2.0;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--plain") == 0) {
      plain = 1;
    } else if (strcmp(argv[i], "--fine-grid") == 0) {
      fine_grid = 1;
    } else if (strcmp(argv[i], "--seconds") == 0 && i + 1 < argc) {
      seconds = atof(argv[++i]);
    } else {
      fprintf(stderr, "usage: flatland_mujoco_render [--plain] [--fine-grid] [--seconds S]\n");
      return 2;
    }
  }
  // MuJoCo renders into its own offscreen framebuffer; this buffer only makes the context current.
  OSMesaContext ctx = OSMesaCreateContextExt(OSMESA_RGBA, 24, 8, 8, NULL);
  static unsigned char buffer[64 * 64 * 4];
  if (!ctx || !OSMesaMakeCurrent(ctx, buffer, GL_UNSIGNED_BYTE, 64, 64)) {
    fprintf(stderr, "flatland_mujoco_render: cannot make an OSMesa context\n");
    return 1;
  }
  char error[1000];
  mjVFS vfs;
  mj_defaultVFS(&vfs);
  mj_makeEmptyFileVFS(&vfs, "m.xml", 10000);
  int f = mj_findFileVFS(&vfs, "m.xml");
  snprintf((char*)vfs.filedata[f], 10000, kModelFormat, fine_grid ? "0.01" : "0.5");
  vfs.filesize[f] = (int)strlen((char*)vfs.filedata[f]);
  mjModel* m = mj_loadXML("m.xml", &vfs, error, sizeof error);
  if (!m) {
    fprintf(stderr, "flatland_mujoco_render: %s\n", error);
    return 1;
  }
  mjData* d = mj_makeData(m);
  mj_forward(m, d);
  mjvScene scn;
  mjvCamera cam;
  mjvOption opt;
  mjrContext con;
  mjv_defaultScene(&scn);
  mjv_defaultCamera(&cam);
  mjv_defaultOption(&opt);
  mjr_defaultContext(&con);
  mjv_makeScene(m, &scn, 1000);
  if (plain) {
    scn.flags[mjRND_SHADOW] = 0;
    scn.flags[mjRND_REFLECTION] = 0;
    scn.flags[mjRND_SKYBOX] = 0;
  }
  mjr_makeContext(m, &con, mjFONTSCALE_100);
  mjr_setBuffer(mjFB_OFFSCREEN, &con);
  cam.type = mjCAMERA_FIXED;
  cam.fixedcamid = 0;
  mjrRect vp = {0, 0, 640, 480};
  unsigned char* rgb = malloc(640 * 480 * 3);
  // One frame first: MuJoCo uploads its textures and compiles its shaders then.
  mjv_updateScene(m, d, &opt, NULL, &cam, mjCAT_ALL, &scn);
  mjr_render(vp, &scn, &con);
  mjr_readPixels(rgb, NULL, vp, &con);
  int n = 0;
  const double start = now();
  double elapsed = 0;
  do {
    mjv_updateScene(m, d, &opt, NULL, &cam, mjCAT_ALL, &scn);
    mjr_render(vp, &scn, &con);
    mjr_readPixels(rgb, NULL, vp, &con);
    ++n;
    elapsed = now() - start;
  } while (elapsed < seconds);
  long sum = 0;
  for (int i = 0; i < 640 * 480 * 3; ++i) sum += rgb[i];
  printf(
      "{\"frames\": %d, \"ms_per_frame\": %.4f, \"mean_dn\": %.2f, \"samples\": %d, "
      "\"plain\": %s, \"fine_grid\": %s, \"gl\": \"%s\"}\n",
      n, 1e3 * elapsed / n, (double)sum / (640.0 * 480 * 3), m->vis.quality.offsamples,
      plain ? "true" : "false", fine_grid ? "true" : "false", (const char*)glGetString(GL_RENDERER));
  free(rgb);
  mjr_freeContext(&con);
  mjv_freeScene(&scn);
  mj_deleteData(d);
  mj_deleteModel(m);
  OSMesaDestroyContext(ctx);
  return 0;
}
