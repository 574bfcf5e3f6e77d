// The dashboard's front end: plain ES modules, built into web/dist, which
// the Python server (python/scattertrack/server/app.py) serves. Relative
// asset paths so the page works under any prefix the server is given.
import { defineConfig } from "vite";

export default defineConfig({
  base: "./",
  build: { outDir: "dist", emptyOutDir: true },
});
