// Requests to the dashboard's API. A token given in the page's address
// (?token=T) goes with every request as a Bearer header, so that the
// server's token rule (python/scattertrack/server/auth.py) lets them in.
const token = new URLSearchParams(location.search).get("token");

function headers(extra = {}) {
  return token ? { ...extra, Authorization: `Bearer ${token}` } : extra;
}

async function answer(response) {
  const body = await response.json().catch(() => ({}));
  if (!response.ok) throw new Error(typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail ?? body));
  return body;
}

export async function get(path) {
  return answer(await fetch(path, { headers: headers() }));
}

export async function post(path, data) {
  const form = data instanceof FormData;
  return answer(await fetch(path, {
    method: "POST",
    headers: form ? headers() : headers({ "Content-Type": "application/json" }),
    body: form ? data : JSON.stringify(data ?? {}),
  }));
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Poll a job until it ends; onProgress(job) after every poll.
export async function waitForJob(id, onProgress = () => {}) {
  for (;;) {
    const job = await get(`/api/jobs/${id}`);
    onProgress(job);
    if (job.state === "done") return job.result;
    if (job.state !== "running") throw new Error(job.error ?? job.state);
    await sleep(300);
  }
}
