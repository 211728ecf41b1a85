// Checks deploy/k8s offline: every document of every manifest against the Kubernetes (and KEDA)
// schemas of the kubernetes-models packages, the kustomization's list against the folder, and
// what softid's deployment relies on (roles, the shared store and volume, probes, autoscaling).
// Usage: node validate.mjs DEPLOY_K8S_DIR   (exit 0 when every check passes)
import { readFileSync, readdirSync } from "node:fs";
import path from "node:path";
import YAML from "yaml";

const MODELS = {
  "v1/Namespace": "kubernetes-models/v1/Namespace",
  "v1/Secret": "kubernetes-models/v1/Secret",
  "v1/Service": "kubernetes-models/v1/Service",
  "v1/PersistentVolumeClaim": "kubernetes-models/v1/PersistentVolumeClaim",
  "apps/v1/Deployment": "kubernetes-models/apps/v1/Deployment",
  "apps/v1/StatefulSet": "kubernetes-models/apps/v1/StatefulSet",
  "keda.sh/v1alpha1/ScaledObject": "@kubernetes-models/keda/keda.sh/v1alpha1/ScaledObject",
  "keda.sh/v1alpha1/TriggerAuthentication":
    "@kubernetes-models/keda/keda.sh/v1alpha1/TriggerAuthentication",
};

const failures = [];
const fail = (message) => failures.push(message);

async function validateDocument(file, doc) {
  const key = `${doc.apiVersion}/${doc.kind}`;
  const module = MODELS[key];
  if (!module) return fail(`${file}: ${key} has no schema here`);
  const Model = (await import(module))[doc.kind];
  try {
    new Model(doc).validate();
  } catch (error) {
    fail(`${file}: ${key} ${doc.metadata?.name}: ${error.message}`);
  }
}

function envOf(deployment) {
  const env = {};
  for (const e of deployment.spec.template.spec.containers[0].env ?? []) env[e.name] = e;
  return env;
}

function checkSoftidDeployment(name, deployment, role) {
  const pod = deployment.spec.template.spec;
  const env = envOf(deployment);
  if (env.SOFTID_ROLE?.value !== role) fail(`${name}: SOFTID_ROLE must be ${role}`);
  if (env.SOFTID_STORE?.valueFrom?.secretKeyRef?.name !== "softid-store")
    fail(`${name}: SOFTID_STORE must come from the softid-store secret`);
  const container = pod.containers[0];
  for (const probe of ["readinessProbe", "livenessProbe"]) {
    if (!container[probe]?.exec?.command?.includes("health")) fail(`${name}: no ${probe} by health`);
  }
  if (!pod.volumes?.some((v) => v.persistentVolumeClaim?.claimName === "softid-data"))
    fail(`${name}: must mount the softid-data volume`);
  if (!(pod.terminationGracePeriodSeconds >= 30)) fail(`${name}: grace period under 30 s`);
  if (!container.resources?.requests?.cpu) fail(`${name}: no CPU request`);
}

const dir = process.argv[2];
const kustomization = YAML.parse(readFileSync(path.join(dir, "kustomization.yaml"), "utf8"));
const files = readdirSync(dir).filter((f) => f.endsWith(".yaml") && f !== "kustomization.yaml");
for (const f of files) if (!kustomization.resources.includes(f)) fail(`kustomization: ${f} not listed`);
for (const f of kustomization.resources) if (!files.includes(f)) fail(`kustomization: ${f} missing`);

const byKindName = {};
for (const file of files) {
  for (const parsed of YAML.parseAllDocuments(readFileSync(path.join(dir, file), "utf8"))) {
    if (parsed.errors.length > 0) fail(`${file}: ${parsed.errors[0].message}`);
    const doc = parsed.toJS();
    if (doc === null) continue;
    await validateDocument(file, doc);
    byKindName[`${doc.kind}/${doc.metadata?.name}`] = doc;
  }
}
const api = byKindName["Deployment/softid-api"];
const worker = byKindName["Deployment/softid-worker"];
if (!api || !worker) fail("need Deployments softid-api and softid-worker");
if (api) checkSoftidDeployment("softid-api", api, "api");
if (worker) checkSoftidDeployment("softid-worker", worker, "worker");
const claim = byKindName["PersistentVolumeClaim/softid-data"];
if (!claim?.spec.accessModes.includes("ReadWriteMany")) fail("softid-data must be ReadWriteMany");
const scaled = byKindName["ScaledObject/softid-worker"];
if (scaled?.spec.scaleTargetRef.name !== "softid-worker") fail("no ScaledObject for the workers");
const query = scaled?.spec.triggers?.[0]?.metadata?.query ?? "";
if (!/FROM jobs WHERE state/.test(query)) fail(`the autoscaling query does not count jobs: ${query}`);
if (!byKindName["Service/softid-api"]) fail("no Service for the API");

if (failures.length > 0) {
  for (const f of failures) console.error(`FAIL: ${f}`);
  process.exit(1);
}
console.log(`ok: ${Object.keys(byKindName).length} documents in ${files.length} files valid`);
