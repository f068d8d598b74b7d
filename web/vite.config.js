// Builds the dashboard into dist/ with fixed file names, which the service embeds
// (src/http/dashboard.rs): index.html, assets/app.js and assets/app.css.
import { defineConfig } from "vite";

// `npm run dev` serves the source with live reload and forwards the API to a running
// `aortagen serve` (AORTAGEN_URL, default http://127.0.0.1:8080).
const api = process.env.AORTAGEN_URL ?? "http://127.0.0.1:8080";
const proxy = Object.fromEntries(["/v1", "/docs", "/openapi.json"].map((p) => [p, { target: api }]));

export default defineConfig({
  base: "/",
  server: { proxy },
  preview: { proxy },
  build: {
    outDir: "dist",
    emptyOutDir: true,
    assetsInlineLimit: 0,
    modulePreload: { polyfill: false },
    chunkSizeWarningLimit: 1024,
    rollupOptions: {
      output: {
        entryFileNames: "assets/app.js",
        chunkFileNames: "assets/app-[name].js",
        assetFileNames: (info) =>
          (info.names ?? [info.name]).some((n) => n && n.endsWith(".css"))
            ? "assets/app.css"
            : "assets/[name][extname]",
      },
    },
  },
});
