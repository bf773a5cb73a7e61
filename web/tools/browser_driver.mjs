// Drives Debian's headless Chromium (/usr/bin/chromium, never a downloaded one) with
// playwright-core for the browser tests (tests/web) and the benchmark
// (tools/bench/bench_web_probes.py). A JSON-lines server: one request per stdin line, one
// response per stdout line ({"id", "ok", "result" | "error"}); diagnostics go to stderr.
//
//   {"id": 1, "op": "open", "url": "...", "width": 160, "height": 120, "page_timeout": 120000}
//       a fresh browser context (empty cache) and page; waits until window.voxgi.state is
//       'ready' or 'error'; result {state, error, timings, console: [{type, text}], pageErrors}
//   {"id": 2, "op": "eval", "expr": "..."}   page.evaluate(expr) in the open page
//   {"id": 3, "op": "console"}               console messages of the open page so far
//   {"id": 4, "op": "screenshot", "path": "x.png"}
//   {"id": 5, "op": "quit"}
//
// Launch flags: WebGL2 through ANGLE on SwiftShader (no GPU here); no background networking
// (the machine has no network but the package registries). Playwright gives every launch a
// fresh temporary --user-data-dir.

import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const EXECUTABLE = process.env.VOXGI_CHROMIUM || '/usr/bin/chromium';
const ARGS = [
	'--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
	'--disable-background-networking', '--disable-component-update', '--disable-sync',
	'--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
];

const browser = await chromium.launch( { executablePath: EXECUTABLE, headless: true, args: ARGS } );
let context = null, page = null, messages = [], pageErrors = [];

function send( object ) {

	process.stdout.write( JSON.stringify( object ) + '\n' );

}

async function open( { url, width = 640, height = 480, page_timeout: timeout = 120000 } ) {

	if ( context ) await context.close();
	context = await browser.newContext( { viewport: { width, height } } );
	page = await context.newPage();
	messages = [];
	pageErrors = [];
	page.on( 'console', ( m ) => messages.push( { type: m.type(), text: m.text() } ) );
	page.on( 'pageerror', ( e ) => pageErrors.push( String( e && e.stack || e ) ) );
	await page.goto( url, { timeout } );
	await page.waitForFunction( () => window.voxgi && window.voxgi.state !== 'loading', null, { timeout, polling: 50 } );
	const state = await page.evaluate( () => ( {
		state: window.voxgi.state, error: window.voxgi.error, timings: window.voxgi.timings,
		probeErrors: window.voxgi.probeErrors,
	} ) );
	return { ...state, console: messages, pageErrors };

}

const lines = createInterface( { input: process.stdin } );
for await ( const line of lines ) {

	if ( ! line.trim() ) continue;
	let request;
	try {

		request = JSON.parse( line );

	} catch ( error ) {

		send( { id: null, ok: false, error: `bad request: ${error.message}` } );
		continue;

	}

	const { id, op } = request;
	try {

		let result;
		if ( op === 'open' ) result = await open( request );
		else if ( op === 'eval' ) {

			if ( ! page ) throw new Error( 'no page is open' );
			result = await page.evaluate( request.expr );

		} else if ( op === 'screenshot' ) {

			if ( ! page ) throw new Error( 'no page is open' );
			await page.screenshot( { path: request.path } );
			result = request.path;

		} else if ( op === 'console' ) result = { console: messages, pageErrors };
		else if ( op === 'quit' ) {

			send( { id, ok: true, result: null } );
			break;

		} else throw new Error( `unknown op ${op}` );
		send( { id, ok: true, result: result === undefined ? null : result } );

	} catch ( error ) {

		send( { id, ok: false, error: String( error && error.stack || error ), console: messages, pageErrors } );

	}

}

await browser.close();
process.exit( 0 );
